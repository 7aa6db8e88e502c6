#!/usr/bin/env bash
# The Raspberry Pi half of the graph: serial_node, next to the Arduino, in ROS domain
# ROS_DOMAIN_ID (default 0). The Arduino is SERIAL_PORT, else /dev/eezybot (the udev rule
# in deploy/), else /dev/ttyACM0. If none exists, serial_node starts on /dev/eezybot
# anyway and connects when the board is plugged in (it never falls back to the virtual
# Arduino by itself); SERIAL_PORT=mock runs the built-in virtual Arduino instead, and
# SERIAL_PORT=twin drives the physics twin running on this host (docs/twin.md).
# Uses the prebuilt binaries in bin/ when they are there (a bundle from
# cross_build.sh), so the Pi needs no Rust toolchain.
#
# SROS2: with ROS_SECURITY_ENABLE=true serial_node runs under the enclave /eezybot/pi of
# ROS_SECURITY_KEYSTORE (only enclaves/eezybot/pi is needed on the Pi; README: Securing
# the link; deploy/install.sh --keystore).
#
# WAN mode (README: Across the internet): with ZENOH_ROUTER=tls/HOST:PORT a bridge
# (eezybot_wan_bridge pi) runs beside the node and carries the contract's topics
# through that Zenoh router to pc.sh on the PC, wherever it is; TLS files from
# ZENOH_TLS_DIR (launch_scripts/wan_certs.sh; ZENOH_CERT: another client certificate
# name). A bad endpoint or TLS file: exit 2 before anything starts. With SROS2 on as
# well, the bridge joins the secured LAN under the enclave /eezybot/bridge_pi of the same
# keystore (docs/security.md: SROS2 with the WAN).
#
# The arm configuration: ARM_CONFIG=FILE, else the calibration wizard's saved
# ${XDG_CONFIG_HOME:-~/.config}/eezybot/arm.yaml if it exists (copy it here from the PC
# where the wizard saved it), else the shipped one.
#
# Arguments are ROS arguments for serial_node, e.g.
#   launch_scripts/pi.sh -r __ns:=/arm2
# Ctrl-C (or SIGTERM) stops it; the script then exits 0.
set -euo pipefail
EEZYBOT_SCRIPT=pi.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

eezybot_find_binaries serial_node
eezybot_ros_args "$@"
eezybot_serial_port
eezybot_security /eezybot/pi serial_node
eezybot_enclave /eezybot/pi
eezybot_wan pi

eezybot_arm_config
eezybot_start serial_node "${EEZYBOT_ENCLAVE[@]}" -p "port:=$EEZYBOT_PORT" "${EEZYBOT_ARM_ARGS[@]}"
eezybot_start_wan

eezybot_banner
if [ "$EEZYBOT_PORT" = mock ]; then
  eezybot_say "running here (Pi): serial_node with the built-in virtual Arduino (SERIAL_PORT=mock)"
elif [ "$EEZYBOT_PORT" = twin ]; then
  eezybot_say "running here: serial_node on the physics twin's link (SERIAL_PORT=twin): the twin must run on this host, in this domain and namespace (\`twin\`, docs/twin.md)"
elif [ "$EEZYBOT_PORT_FOUND" = 1 ]; then
  eezybot_say "running here (Pi): serial_node on $EEZYBOT_PORT"
else
  eezybot_say "WARNING: no Arduino at ${SERIAL_PORT:-/dev/eezybot or /dev/ttyACM0}; serial_node waits for $EEZYBOT_PORT to appear"
  eezybot_say "(plug in the board, check the udev rule and the dialout group; SERIAL_PORT=mock for the virtual Arduino)"
  eezybot_say "running here (Pi): serial_node on $EEZYBOT_PORT (not connected yet)"
fi
eezybot_wan_banner
if [ "$EEZYBOT_WAN" = 1 ]; then
  eezybot_say "expected on the PC (pc.sh with ZENOH_ROUTER, through the router): compute_ik, state_publisher, gui_bridge"
else
  eezybot_say "expected on the PC (pc.sh, same ROS domain): compute_ik, state_publisher, gui_bridge"
fi
eezybot_wait
