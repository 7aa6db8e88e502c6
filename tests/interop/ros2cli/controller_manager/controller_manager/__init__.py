# Copyright (c) 2021 PAL Robotics S.L.
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

from .controller_manager_services import (
    configure_controller,
    list_controller_types,
    list_controllers,
    list_hardware_components,
    list_hardware_interfaces,
    load_controller,
    reload_controller_libraries,
    set_hardware_component_state,
    switch_controllers,
    unload_controller,
    cleanup_controller,
    get_parameter_from_param_files,
    set_controller_parameters,
    set_controller_parameters_from_param_files,
    bcolors,
)

__all__ = [
    "configure_controller",
    "list_controller_types",
    "list_controllers",
    "list_hardware_components",
    "list_hardware_interfaces",
    "load_controller",
    "reload_controller_libraries",
    "set_hardware_component_state",
    "switch_controllers",
    "unload_controller",
    "cleanup_controller",
    "get_parameter_from_param_files",
    "set_controller_parameters",
    "set_controller_parameters_from_param_files",
    "bcolors",
]
