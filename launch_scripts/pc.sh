#!/usr/bin/env bash
# The operator's PC half of the graph: gui_bridge (web panel on GUI_BIND, default
# 127.0.0.1:8080; 0.0.0.0:8080 to reach it from another machine, over HTTPS with
# GUI_TLS_DIR from launch_scripts/panel_certs.sh, or GUI_TLS_CERT and GUI_TLS_KEY; plain
# HTTP there only with GUI_INSECURE_HTTP=1, the token then in the clear), compute_ik and
# state_publisher, in ROS domain ROS_DOMAIN_ID (default 0). Run pi.sh on the Raspberry
# Pi next to the Arduino, in the same domain, on the same network (multicast allowed).
#
# SROS2: with ROS_SECURITY_ENABLE=true every node runs under the enclave /eezybot/pc of
# ROS_SECURITY_KEYSTORE (launch_scripts/keystore.sh; README: Securing the link).
#
# WAN mode (README: Across the internet): with ZENOH_ROUTER=tls/HOST:PORT a bridge
# (eezybot_wan_bridge pc) runs beside the nodes and carries the contract's topics
# through that Zenoh router to pi.sh on the Pi, wherever it is; TLS files from
# ZENOH_TLS_DIR (launch_scripts/wan_certs.sh; ZENOH_CERT: another client certificate
# name). A bad endpoint or TLS file: exit 2 before anything starts. With SROS2 on as
# well, the bridge joins the secured LAN under the enclave /eezybot/bridge_pc of the same
# keystore (docs/security.md: SROS2 with the WAN).
#
# The arm configuration: ARM_CONFIG=FILE, else the calibration wizard's saved
# ${XDG_CONFIG_HOME:-~/.config}/eezybot/arm.yaml if it exists, else the shipped one.
# On two machines, copy the file the wizard saved to the same path on the other one.
#
# Arguments are ROS arguments for every node, e.g.
#   launch_scripts/pc.sh -r __ns:=/arm2
# Ctrl-C (or SIGTERM) stops every node; the script then exits 0.
set -euo pipefail
EEZYBOT_SCRIPT=pc.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

eezybot_find_binaries compute_ik state_publisher gui_bridge
eezybot_ros_args "$@"
eezybot_gui
eezybot_security /eezybot/pc "compute_ik, state_publisher, gui_bridge"
eezybot_enclave /eezybot/pc
eezybot_wan pc

eezybot_arm_config
eezybot_start compute_ik "${EEZYBOT_ENCLAVE[@]}" "${EEZYBOT_ARM_ARGS[@]}"
eezybot_start state_publisher "${EEZYBOT_ENCLAVE[@]}"
eezybot_start gui_bridge "${EEZYBOT_ENCLAVE[@]}" "${EEZYBOT_GUI_ARGS[@]}" "${EEZYBOT_ARM_ARGS[@]}"
eezybot_start_wan

eezybot_banner
eezybot_say "running here (operator PC): compute_ik, state_publisher, gui_bridge"
eezybot_wan_banner
if [ "$EEZYBOT_WAN" = 1 ]; then
  eezybot_say "expected on the Pi (pi.sh with ZENOH_ROUTER, through the router): serial_node"
else
  eezybot_say "expected on the Pi (pi.sh, same ROS domain): serial_node"
fi
eezybot_say "web panel: $EEZYBOT_GUI_URL (Ctrl-C to stop)"
eezybot_wait
