#!/usr/bin/env bash
# The whole EezyBot graph on this machine, in one ROS domain (ROS_DOMAIN_ID, default 0):
# gui_bridge (web panel on GUI_BIND, default 127.0.0.1:8080), compute_ik,
# state_publisher and serial_node. serial_node drives the Arduino on SERIAL_PORT, or else
# on /dev/eezybot or /dev/ttyACM0; when none of them exists it uses the built-in virtual
# Arduino (SERIAL_PORT=mock asks for it), and says so.
#
# Arguments are ROS arguments for every node, e.g.
#   launch_scripts/run_graph.sh -r __ns:=/arm2
# Ctrl-C (or SIGTERM) stops every node; the script then exits 0.
# Split across two machines: pc.sh on the operator's PC, pi.sh next to the Arduino.
set -euo pipefail
EEZYBOT_SCRIPT=run_graph.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

eezybot_find_binaries compute_ik state_publisher serial_node gui_bridge
eezybot_ros_args "$@"
eezybot_serial_port
if [ "$EEZYBOT_PORT_FOUND" = 0 ]; then
  eezybot_say "no Arduino at ${SERIAL_PORT:-/dev/eezybot or /dev/ttyACM0}: using the built-in virtual Arduino"
  EEZYBOT_PORT=mock
fi
bind=${GUI_BIND:-127.0.0.1:8080}

eezybot_start compute_ik
eezybot_start state_publisher
eezybot_start serial_node -p "port:=$EEZYBOT_PORT"
eezybot_start gui_bridge -p "bind:=$bind"

eezybot_banner
eezybot_say "running here: compute_ik, state_publisher, gui_bridge, serial_node ($([ "$EEZYBOT_PORT" = mock ] && echo "virtual Arduino" || echo "Arduino on $EEZYBOT_PORT"))"
eezybot_say "web panel: http://$bind/ (Ctrl-C to stop)"
eezybot_say "try: ros2 topic pub --once /xyz_target geometry_msgs/msg/PointStamped \"{header: {frame_id: base_link}, point: {x: 0.2, y: 0.0, z: 0.15}}\""
eezybot_wait
