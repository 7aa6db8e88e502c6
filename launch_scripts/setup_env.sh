#!/usr/bin/env bash
# Installs what the tests and tools need, idempotently and quietly, and exports
# EEZYBOT_PYTHON (a Python 3.11 venv with real ROS 2 from PyPI).
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
# and libclang-dev (the cyclors crate builds Cyclone DDS and binds it with bindgen).
EEZYBOT_APT_PACKAGES=${EEZYBOT_APT_PACKAGES:-gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev chromium clang libclang-rt-14-dev libssl-dev pkg-config libfastrtps-dev g++ tcpdump cmake libclang-dev}
. "$_here/launch_scripts/apt_missing.sh"
# shellcheck disable=SC2086 # a list of words
apt_missing setup $EEZYBOT_APT_PACKAGES

# Python venv, cached per requirements file content.
_req="$_here/tests/requirements.txt"
_hash=$(sha256sum "$_req" | cut -c1-12)
_venv="${EEZYBOT_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/eezybot/venv-$_hash}"
if [ ! -f "$_venv/.complete" ]; then
  _py=""
  for c in python3.11 python3; do
    if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      _py=$(command -v "$c"); break
    fi
  done
  [ -n "$_py" ] || { _log "Python 3.11 is required for the ROS 2 wheels"; exit 1; }
  _log "creating the ROS 2 Python venv in $_venv (once)"
  rm -rf "$_venv"
  "$_py" -m venv "$_venv"
  "$_venv/bin/pip" install -q --disable-pip-version-check -r "$_req"
  "$_venv/bin/python" -c 'import rclpy, cyclonedds, pytest, playwright'
  touch "$_venv/.complete"
fi
export EEZYBOT_PYTHON="$_venv/bin/python"
