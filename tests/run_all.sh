#!/usr/bin/env bash
# Every test of the project: Rust unit, property and doc tests, then the
# integration tests that run our real binaries against real ROS 2 (rclpy, Fast DDS,
# Cyclone DDS). Installs what it needs on first run.
set -euo pipefail
cd "$(dirname "$0")/.."
. launch_scripts/setup_env.sh
export CARGO_TERM_QUIET=true
# each stage says how long the one before it took, and the total at the end
stage_start=$SECONDS
stage() {
  [ -z "${stage_name:-}" ] || echo "   ($stage_name: $((SECONDS - stage_start)) s)"
  stage_name=$1 stage_start=$SECONDS
  [ -z "$1" ] || echo "== $1"
}
trap 'stage ""; echo "== all stages: $SECONDS s"' EXIT
stage "firmware (avr-gcc) and its simavr harness"
make -s -C firmware/servo_control all sim
stage "cargo build"
cargo build --workspace --bins --examples
stage "cargo test"
cargo test --workspace
# The patched crates' checks and tests (tests/check_patches.sh: a dependency tree and
# target directory of their own) build alongside the Raspberry Pi stage, whose OpenSSL
# build and emulated tests leave a core idle much of the time; their output follows it.
stage "Raspberry Pi: cross-build (aarch64, profile pi-check), pure crates' tests under qemu-aarch64; alongside: the patched crates (tests/check_patches.sh), then the WAN mode's binaries (wan/)"
# The WAN mode's router and bridge (wan/: its own workspace, Zenoh and Cyclone DDS, about
# 11 CPU-minutes from nothing) build into a target directory kept per machine, as the
# Pi's OpenSSL is (EEZYBOT_WAN_TARGET; `off`: wan/target of this checkout): a fresh clone
# then compiles only the crates of its own tree (our binaries and the patched plugin,
# wan/patches/), about a minute. tests/test_wan*.py run them (EEZYBOT_WAN_BIN_DIR).
wan_target=${EEZYBOT_WAN_TARGET:-${XDG_CACHE_HOME:-$HOME/.cache}/eezybot/wan-target}
[ "$wan_target" != off ] || wan_target=$PWD/wan/target
export EEZYBOT_WAN_BIN_DIR=$wan_target/release
patches_log=$(mktemp)
{ tests/check_patches.sh && (cd wan && CARGO_TARGET_DIR=$wan_target cargo build --release --locked); } >"$patches_log" 2>&1 &
patches_pid=$!
# (stopped with its cargo if a stage before its end fails)
trap '[ -z "$patches_pid" ] || pkill -TERM -P "$patches_pid" cargo 2>/dev/null || true
      [ -z "$patches_pid" ] || kill "$patches_pid" 2>/dev/null || true
      rm -f "$patches_log"; stage ""; echo "== all stages: $SECONDS s"' EXIT
. launch_scripts/setup_cross.sh
# pi-check (Cargo.toml): the release's toolchain, OpenSSL and checks in less time than
# profile pi; the tests under qemu share its dependencies
EEZYBOT_PI_PROFILE=pi-check launch_scripts/cross_build.sh aarch64
# the pure crates the Pi runs (servo mapping, motion limits, framing, the host link):
# their unit tests and properties, with 10 cases each under emulation (200 natively,
# above): the target's arithmetic, not a second search of the input space. Not the
# kinematics tests of what only the PC runs (IK, URDF chains, workspace envelopes:
# envelope.rs alone took 36 s under qemu), nor eezybot_msgs: its test build needs the
# whole DDS stack again, with other features than serial_node's above (about a minute
# of the stage), for CDR that cdr_encoding writes little-endian on every target.
PROPTEST_CASES=10 cargo test --profile pi-check --target aarch64-unknown-linux-gnu \
  -p eezybot_kinematics -p servo_protocol --lib --test properties
stage "patched crates: resolved from patches/, and their unit tests (tests/check_patches.sh), and wan/ built (started above)"
patches_code=0
wait "$patches_pid" || patches_code=$?
patches_pid=
cat "$patches_log"
[ "$patches_code" = 0 ] || { echo "tests/check_patches.sh or the build of wan/ failed (exit $patches_code)"; exit 1; }
stage "integration tests (real ROS 2)"
"$EEZYBOT_PYTHON" -m pytest tests -q -p no:cacheprovider --durations=15 "$@"
