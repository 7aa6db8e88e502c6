#!/usr/bin/env bash
# Runs the whole EezyBot graph that exists on this machine, in one ROS domain
# (ROS_DOMAIN_ID, default 0). Ctrl-C stops every node.
#
# Nodes: gui_bridge (web panel on http://127.0.0.1:8080, or GUI_BIND), compute_ik,
# state_publisher, serial_node. serial_node uses the Arduino on SERIAL_PORT (default
# /dev/ttyACM0) if it exists, else the built-in virtual Arduino.
# Extra ROS arguments for every node can follow, e.g.
#   launch_scripts/run_graph.sh -r __ns:=/arm2
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet --bins
bin=target/release
pids=()
stop() {
  trap - INT TERM EXIT
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done
  wait
}
trap stop INT TERM EXIT

ros_args=()
[ $# -gt 0 ] && ros_args=(--ros-args "$@")

"$bin/compute_ik" "${ros_args[@]}" & pids+=($!)
"$bin/state_publisher" "${ros_args[@]}" & pids+=($!)
port=${SERIAL_PORT:-/dev/ttyACM0}
[ -e "$port" ] || port=mock
"$bin/serial_node" --ros-args -p "port:=$port" "$@" & pids+=($!)
bind=${GUI_BIND:-127.0.0.1:8080}
"$bin/gui_bridge" --ros-args -p "bind:=$bind" "$@" & pids+=($!)

echo "graph running in ROS domain ${ROS_DOMAIN_ID:-0}: compute_ik, state_publisher, serial_node (port $port), gui_bridge" >&2
echo "open http://$bind/ (Ctrl-C to stop)" >&2
echo "try: ros2 topic pub --once /xyz_target geometry_msgs/msg/PointStamped \"{header: {frame_id: base_link}, point: {x: 0.2, y: 0.0, z: 0.15}}\"" >&2
wait -n "${pids[@]}"
