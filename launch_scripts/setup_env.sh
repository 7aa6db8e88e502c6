#!/usr/bin/env bash
# Installs what the tests and tools need, idempotently and quietly, and exports
# EEZYBOT_PYTHON (a Python 3.11 venv with real ROS 2 Kilted from PyPI) and
# EEZYBOT_JAZZY_PYTHON (the same with ROS 2 Jazzy).
# Source it (`. launch_scripts/setup_env.sh`) or run it; safe to repeat.
set -euo pipefail
_here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

_log() { echo "[setup] $*" >&2; }

# Debian packages: the AVR toolchain and Arduino core for the firmware, simavr for its
# tests, Chromium for the browser tests of the web panel; for DDS Security (SROS2):
# OpenSSL's headers and pkg-config (the nodes' `security` build), Debian's Fast DDS 2.9
# with its security plugins plus g++ (tests/interop/sros2_peer, the secured interop
# peer: the PyPI Fast DDS and Cyclone wheels are built without security) and tcpdump
# (the wire captures of tests/test_security.py); for the WAN mode's bridge (wan/): cmake
# and libclang-dev (the cyclors crate builds Cyclone DDS and binds it with bindgen); for
# control_msgs in the test venvs (launch_scripts/gen_control_msgs.sh): cmake, gcc, g++
# and Python 3.11's headers (python3.11-dev, when the venvs use Debian's Python); for the
# camera videos of LeRobot datasets (libs/lerobot_dataset): ffmpeg (5.1, with libsvtav1);
# for the web panel over HTTPS (tests/test_panel_tls.py): NSS's certutil (libnss3-tools),
# which makes the throwaway certificate store in which Chromium trusts the test's CA.
EEZYBOT_APT_PACKAGES=${EEZYBOT_APT_PACKAGES:-gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev chromium clang libclang-rt-14-dev libssl-dev pkg-config libfastrtps-dev g++ tcpdump cmake libclang-dev gcc python3.11-dev ffmpeg libnss3-tools}
. "$_here/launch_scripts/apt_missing.sh"
# shellcheck disable=SC2086 # a list of words
apt_missing setup $EEZYBOT_APT_PACKAGES

# Python venvs of real ROS 2 from PyPI wheels, each cached per the content of its
# requirements file and of what builds control_msgs into it (no wheel of it exists:
# launch_scripts/gen_control_msgs.sh generates its type support with the rosidl
# generator wheels): EEZYBOT_PYTHON, Kilted (tests/requirements.txt: rclpy 9.x, what the
# tests run in), and EEZYBOT_JAZZY_PYTHON, Jazzy (tests/requirements-jazzy.txt: rclpy
# 7.x, the LTS most users run; tests/test_jazzy.py drives it). A venv is complete once
# it has `.complete`; two setups at once take turns (flock).
_python311() {
  local c
  for c in python3.11 python3; do
    if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      command -v "$c"; return 0
    fi
  done
  _log "Python 3.11 is required for the ROS 2 wheels"; return 1
}
# _ros_venv VAR REQUIREMENTS DISTRO DIR IMPORTS: the python of the venv DIR (default: its
# place in the cache, keyed by the hash) in VAR
_ros_venv() {
  local var=$1 req=$2 distro=$3 venv=$4 imports=$5 py
  if [ ! -f "$venv/.complete" ]; then
    py=$(_python311)
    mkdir -p "$(dirname "$venv")"
    (
      flock 9
      if [ ! -f "$venv/.complete" ]; then
        _log "creating the ROS 2 ($distro) Python venv in $venv (once)"
        rm -rf "$venv"
        "$py" -m venv "$venv"
        "$venv/bin/pip" install -q --disable-pip-version-check -r "$req"
        bash "$_here/launch_scripts/gen_control_msgs.sh" "$venv" "$distro"
        if [ "$distro" = kilted ]; then bash "$_here/launch_scripts/install_ros2cli.sh" "$venv"; fi
        "$venv/bin/python" -c "import $imports"
        touch "$venv/.complete"
      fi
    ) 9>"$venv.lock"
  fi
  printf -v "$var" %s "$venv/bin/python"
}
_venv_hash() {
  { cat "$1"; bash "$_here/launch_scripts/gen_control_msgs.sh" --inputs
    if [ "${2:-}" = kilted ]; then bash "$_here/launch_scripts/install_ros2cli.sh" --inputs; fi
  } | sha256sum | cut -c1-12
}
_cache="${XDG_CACHE_HOME:-$HOME/.cache}/eezybot"
_req="$_here/tests/requirements.txt"
_ros_venv EEZYBOT_PYTHON "$_req" kilted "${EEZYBOT_VENV:-$_cache/venv-$(_venv_hash "$_req" kilted)}" \
  'rclpy, rclpy.action, cyclonedds, pytest, playwright, trajectory_msgs.msg, control_msgs.action, controller_manager_msgs.srv, ros2cli.cli, ros2controlcli.verb.switch_controllers'
_req="$_here/tests/requirements-jazzy.txt"
_ros_venv EEZYBOT_JAZZY_PYTHON "$_req" jazzy "${EEZYBOT_JAZZY_VENV:-$_cache/venv-jazzy-$(_venv_hash "$_req")}" \
  'rclpy, rclpy.action, trajectory_msgs.msg, control_msgs.action, controller_manager_msgs.srv'
export EEZYBOT_PYTHON EEZYBOT_JAZZY_PYTHON
