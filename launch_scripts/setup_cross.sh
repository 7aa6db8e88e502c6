#!/usr/bin/env bash
# Installs what cross-building for a Raspberry Pi needs, idempotently and quietly (one
# line when it installs something): the Rust targets aarch64-unknown-linux-gnu (64-bit
# Raspberry Pi OS / Ubuntu) and armv7-unknown-linux-gnueabihf (32-bit Raspberry Pi OS),
# Debian's cross gcc + libc for both (the linkers named in .cargo/config.toml), and
# qemu-user, so `cargo test --target ...` runs the tests of pure crates (the cargo runner
# in .cargo/config.toml). Source it (`. launch_scripts/setup_cross.sh`) or run it.
# EEZYBOT_CROSS_WAN=1 (cross_build.sh --wan): also what cross-building wan/'s bridge needs.
set -euo pipefail

_log() { echo "[setup_cross] $*" >&2; }

# Rust targets (rustup downloads the standard library for each once).
EEZYBOT_CROSS_TARGETS=${EEZYBOT_CROSS_TARGETS:-aarch64-unknown-linux-gnu armv7-unknown-linux-gnueabihf}
_installed=$(rustup target list --installed)
_missing=()
for t in $EEZYBOT_CROSS_TARGETS; do
  grep -qx "$t" <<<"$_installed" || _missing+=("$t")
done
if [ ${#_missing[@]} -gt 0 ]; then
  _log "installing Rust targets: ${_missing[*]}"
  _out=$(rustup target add "${_missing[@]}" 2>&1) || { echo "$_out" >&2; exit 1; }
fi

# Debian packages: cross linkers and C libraries, qemu-user (provides qemu-aarch64 and
# qemu-arm, the cargo runners), perl and make (OpenSSL's own build, which openssl-src runs
# for the target: the Pi binaries link OpenSSL statically for DDS Security), libclang-dev
# (camera_node's v4l2-sys-mit runs bindgen on the target's linux/videodev2.h, which
# linux-libc-dev-*-cross brings with the cross C libraries).
EEZYBOT_CROSS_APT_PACKAGES=${EEZYBOT_CROSS_APT_PACKAGES:-gcc-aarch64-linux-gnu libc6-dev-arm64-cross gcc-arm-linux-gnueabihf libc6-dev-armhf-cross qemu-user perl make libclang-dev}
. "$(dirname "${BASH_SOURCE[0]}")/apt_missing.sh"
# shellcheck disable=SC2086 # a list of words
apt_missing setup_cross $EEZYBOT_CROSS_APT_PACKAGES
# wan/'s bridge (cross_build.sh --wan): cyclors builds Cyclone DDS with cmake, a C and C++
# project (`project(... LANGUAGES C CXX)`: without the cross g++ its configure stops at
# "CMAKE_CXX_COMPILER: aarch64-linux-gnu-g++ is not a full path and was not found"), and
# runs bindgen on its headers (libclang).
if [ "${EEZYBOT_CROSS_WAN:-0}" = 1 ]; then
  EEZYBOT_CROSS_WAN_APT_PACKAGES=${EEZYBOT_CROSS_WAN_APT_PACKAGES:-cmake libclang-dev g++-aarch64-linux-gnu g++-arm-linux-gnueabihf}
  # shellcheck disable=SC2086 # a list of words
  apt_missing setup_cross $EEZYBOT_CROSS_WAN_APT_PACKAGES
fi
unset _installed _missing _out
