#!/usr/bin/env bash
# The whole EezyBot graph on this machine, in one ROS domain (ROS_DOMAIN_ID, default 0):
# gui_bridge (web panel on GUI_BIND, default 127.0.0.1:8080; beyond loopback over HTTPS
# with GUI_TLS_DIR, or GUI_TLS_CERT and GUI_TLS_KEY, as pc.sh), compute_ik,
# state_publisher and serial_node. serial_node drives the Arduino on SERIAL_PORT, or else
# on /dev/eezybot or /dev/ttyACM0; when none of them exists it uses the built-in virtual
# Arduino (SERIAL_PORT=mock asks for it), and says so. SERIAL_PORT=twin runs the physics
# twin (MuJoCo, docs/twin.md) beside them and serial_node drives it (port:=twin); in a
# source tree the first run installs MuJoCo and builds the twin.
#
# Another arm: `--arm jaco` as the first arguments (or ARM=jaco) runs compute_ik and
# state_publisher on urdf/jaco.urdf (the Kinova Jaco 2, 6 DOF) with gui_bridge, and no
# serial_node (the Jaco has no hobby servos: compute_ik publishes no servo_angles).
# `--arm eezybot` (the default) is the EezyBotArm.
#
# The arm configuration (geometry, limits, servo calibration): ARM_CONFIG=FILE, else the
# calibration wizard's saved file ${XDG_CONFIG_HOME:-~/.config}/eezybot/arm.yaml if it
# exists, else the shipped config/arm.yaml (ARM_CONFIG= forces it).
#
# SROS2: with ROS_SECURITY_ENABLE=true compute_ik, state_publisher and gui_bridge run
# under the enclave /eezybot/pc and serial_node under /eezybot/pi, of
# ROS_SECURITY_KEYSTORE (launch_scripts/keystore.sh; README: Securing the link).
#
# The other arguments are ROS arguments for every node, e.g.
#   launch_scripts/run_graph.sh -r __ns:=/arm2
#   launch_scripts/run_graph.sh --arm jaco -r __ns:=/jaco
# Ctrl-C (or SIGTERM) stops every node; the script then exits 0.
# Split across two machines: pc.sh on the operator's PC, pi.sh next to the Arduino.
set -euo pipefail
EEZYBOT_SCRIPT=run_graph.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

arm=${ARM:-eezybot}
case "${1:-}" in
  --arm) [ $# -ge 2 ] || { eezybot_say "--arm needs a value: eezybot or jaco"; exit 2; }
         arm=$2; shift 2 ;;
  --arm=*) arm=${1#--arm=}; shift ;;
esac
eezybot_gui

case "$arm" in
  eezybot)
    eezybot_find_binaries compute_ik state_publisher serial_node gui_bridge
    eezybot_ros_args "$@"
    eezybot_serial_port
    if [ "$EEZYBOT_PORT_FOUND" = 0 ]; then
      eezybot_say "no Arduino at ${SERIAL_PORT:-/dev/eezybot or /dev/ttyACM0}: using the built-in virtual Arduino"
      EEZYBOT_PORT=mock
    fi
    [ "$EEZYBOT_PORT" != twin ] || eezybot_twin
    if [ "$EEZYBOT_PORT" = twin ]; then
      eezybot_security /eezybot/pc "compute_ik, state_publisher, gui_bridge, twin" /eezybot/pi serial_node
    else
      eezybot_security /eezybot/pc "compute_ik, state_publisher, gui_bridge" /eezybot/pi serial_node
    fi

    eezybot_arm_config

    eezybot_enclave /eezybot/pc
    eezybot_start compute_ik "${EEZYBOT_ENCLAVE[@]}" "${EEZYBOT_ARM_ARGS[@]}"
    eezybot_start state_publisher "${EEZYBOT_ENCLAVE[@]}"
    eezybot_start gui_bridge "${EEZYBOT_ENCLAVE[@]}" "${EEZYBOT_GUI_ARGS[@]}" "${EEZYBOT_ARM_ARGS[@]}"
    # (the twin is an arm assembled to the shipped config: a calibration of your own
    # then shows in it as on a real arm)
    [ "$EEZYBOT_PORT" != twin ] || eezybot_start twin "${EEZYBOT_ENCLAVE[@]}"
    eezybot_enclave /eezybot/pi
    eezybot_start serial_node "${EEZYBOT_ENCLAVE[@]}" -p "port:=$EEZYBOT_PORT" "${EEZYBOT_ARM_ARGS[@]}"

    eezybot_banner
    case "$EEZYBOT_PORT" in
      mock) device="virtual Arduino" ;;
      twin) device="the physics twin: twin, MuJoCo" ;;
      *) device="Arduino on $EEZYBOT_PORT" ;;
    esac
    eezybot_say "running here: compute_ik, state_publisher, gui_bridge, serial_node ($device)"
    eezybot_say "web panel: $EEZYBOT_GUI_URL (Ctrl-C to stop)"
    eezybot_say "try: ros2 topic pub --once /xyz_target geometry_msgs/msg/PointStamped \"{header: {frame_id: base_link}, point: {x: 0.2, y: 0.0, z: 0.15}}\""
    ;;
  jaco)
    urdf="$EEZYBOT_ROOT/urdf/jaco.urdf"
    [ -f "$urdf" ] || { eezybot_say "no $urdf: --arm jaco runs from a source tree"; exit 1; }
    eezybot_find_binaries compute_ik state_publisher gui_bridge
    eezybot_ros_args "$@"
    eezybot_security /eezybot/pc "compute_ik, state_publisher, gui_bridge"
    eezybot_enclave /eezybot/pc

    eezybot_start compute_ik "${EEZYBOT_ENCLAVE[@]}" -p "urdf:=$urdf" -p "tip_link:=jaco_end_effector"
    eezybot_start state_publisher "${EEZYBOT_ENCLAVE[@]}" -p "urdf:=$urdf"
    eezybot_start gui_bridge "${EEZYBOT_ENCLAVE[@]}" "${EEZYBOT_GUI_ARGS[@]}"

    eezybot_banner
    eezybot_say "arm: Kinova Jaco 2 (6 DOF, $urdf), tip jaco_end_effector; no serial_node (no servos to drive)"
    eezybot_say "running here: compute_ik, state_publisher, gui_bridge"
    eezybot_say "web panel: $EEZYBOT_GUI_URL (Ctrl-C to stop)"
    eezybot_say "try: ros2 topic pub --once /pose_target geometry_msgs/msg/PoseStamped \"{header: {frame_id: base_link}, pose: {position: {x: 0.5, y: 0.0, z: 0.4}, orientation: {x: 0.0, y: 0.7071068, z: 0.0, w: 0.7071068}}}\""
    ;;
  *)
    eezybot_say "unknown arm \`$arm\` (--arm or ARM): eezybot or jaco"
    exit 2
    ;;
esac
eezybot_wait
