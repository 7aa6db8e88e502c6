"""move_group and RViz (MotionPlanning) against the EezyBot graph that is already running.

Starts ONLY move_group and, with use_rviz:=true, RViz. It starts no ros2_control, no
robot_state_publisher and no fake controllers: our graph publishes robot_description,
tf/tf_static (state_publisher) and joint_states, and serves
arm_controller/follow_joint_trajectory, gripper_controller/gripper_cmd and the controller
manager's services that MoveIt switches them with (compute_ik).

    ros2 launch eezybot_moveit_config move_group.launch.py
    ros2 launch eezybot_moveit_config move_group.launch.py namespace:=arm2 use_rviz:=false
    ros2 launch eezybot_moveit_config move_group.launch.py urdf:=/path/to/eezybot.urdf

namespace: the graph's namespace (empty = /). move_group and RViz run in it, so their
relative names (joint_states, the controllers' actions, monitored_planning_scene...) meet
the graph's; tf and tf_static, which MoveIt and RViz use as /tf and /tf_static, are
remapped to the namespace's.
urdf: the robot model MoveIt plans with; it must be the one state_publisher publishes.
The default is the copy of the repository's urdf/eezybot.urdf installed with this package.
"""
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from moveit_configs_utils import MoveItConfigsBuilder

PACKAGE = "eezybot_moveit_config"
ROBOT = "eezybot_arm_mk2"
SRDF = "config/eezybot_arm_mk2.srdf"
KINEMATICS = "config/kinematics.yaml"
JOINT_LIMITS = "config/joint_limits.yaml"
CONTROLLERS = "config/moveit_controllers.yaml"
URDF = "urdf/eezybot.urdf"
RVIZ = "config/moveit.rviz"
TF_REMAPS = [("/tf", "tf"), ("/tf_static", "tf_static")]


def moveit_config(urdf_path):
    return (
        MoveItConfigsBuilder(ROBOT, package_name=PACKAGE)
        .robot_description(file_path=urdf_path)
        .robot_description_semantic(file_path=SRDF)
        .robot_description_kinematics(file_path=KINEMATICS)
        .joint_limits(file_path=JOINT_LIMITS)
        .trajectory_execution(file_path=CONTROLLERS, moveit_manage_controllers=True)
        .planning_scene_monitor(
            publish_planning_scene=True,
            publish_geometry_updates=True,
            publish_state_updates=True,
            publish_transforms_updates=True,
            publish_robot_description=False,  # state_publisher publishes it
            publish_robot_description_semantic=True,
        )
        .planning_pipelines(pipelines=["ompl"], default_planning_pipeline="ompl")
        .to_moveit_configs()
    )


def nodes(context):
    # None, not "", for the root namespace: the Node's own default
    namespace = LaunchConfiguration("namespace").perform(context).strip("/") or None
    urdf_path = Path(LaunchConfiguration("urdf").perform(context)).expanduser()
    config = moveit_config(str(urdf_path.resolve()))

    move_group = Node(
        package="moveit_ros_move_group",
        executable="move_group",
        namespace=namespace,
        output="screen",
        parameters=[
            config.to_dict(),
            {
                "publish_robot_description_semantic": True,
                "allow_trajectory_execution": True,
                # joint_states has no efforts; nothing here needs them
                "monitor_dynamics": False,
                # where the graph's controller manager services are (compute_ik's)
                "ros_control_namespace": "/" + (namespace or ""),
            },
        ],
        remappings=TF_REMAPS,
    )
    rviz = Node(
        package="rviz2",
        executable="rviz2",
        namespace=namespace,
        output="log",
        arguments=["-d", LaunchConfiguration("rviz_config").perform(context)],
        parameters=[
            config.robot_description,
            config.robot_description_semantic,
            config.robot_description_kinematics,
            config.planning_pipelines,
            config.joint_limits,
        ],
        remappings=TF_REMAPS,
        condition=IfCondition(LaunchConfiguration("use_rviz")),
    )
    return [move_group, rviz]


def generate_launch_description():
    share = Path(get_package_share_directory(PACKAGE))
    return LaunchDescription(
        [
            DeclareLaunchArgument("use_rviz", default_value="true", description="start RViz with the MotionPlanning display"),
            DeclareLaunchArgument("namespace", default_value="", description="namespace of the EezyBot graph (empty: /)"),
            DeclareLaunchArgument("urdf", default_value=str(share / URDF), description="URDF that MoveIt plans with (the one state_publisher publishes)"),
            DeclareLaunchArgument("rviz_config", default_value=str(share / RVIZ), description="RViz configuration"),
            OpaqueFunction(function=nodes),
        ]
    )
