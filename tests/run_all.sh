#!/usr/bin/env bash
# The test command: every test of the project that runs on one machine. In order: the
# firmware (avr-gcc) and its simavr harness; the Rust workspace's unit, property and doc
# tests; the Raspberry Pi cross-build and the Pi's pure crates' tests under qemu-aarch64;
# the patched crates' own unit tests (patches/, tests/check_patches.sh) and the WAN
# mode's (wan/: ours and the patched Zenoh plugin's); then the integration tests
# (pytest tests/), which run our real binaries against real ROS 2 (rclpy, Fast DDS,
# Cyclone DDS), simavr and Chromium. Not here: the soaks (tests/soak/) and benchmarks
# (tests/bench/), scripts of their own whose results are in BENCHMARKS.md; the fuzzers'
# long runs (a short run of each is). Installs what it needs on first run.
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

# Compiled crates are kept per machine, outside the checkout, as OpenSSL's Pi build is:
# in ~/.cache/eezybot/ (EEZYBOT_CARGO_CACHE: another directory, or `off`: target/ of
# this checkout, and wan/target), one target directory per build: native-target (the
# binaries the tests run: EEZYBOT_BIN_DIR), patches-target (tests/check_patches.sh),
# pi-target (the aarch64 cross-build) and wan-target (wan/'s release;
# EEZYBOT_WAN_TARGET). A fresh clone then compiles only its own path crates (the
# workspace and the patched copies) and what depends on them; crates.io's crates are
# reused when their versions, features and profile are the same. A directory past 20 GB
# (a path crate's artifacts stay there for each checkout path that built it) is emptied
# first.
cargo_cache=${EEZYBOT_CARGO_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/eezybot}
cargo_target() {  # the target directory of build $1 (emptied first when it grew too big)
  if [ "$cargo_cache" = off ]; then
    case "$1" in native | pi) echo "$PWD/target" ;; patches) echo "$PWD/target/patches" ;; wan) echo "$PWD/wan/target" ;; esac
    return
  fi
  local d=$cargo_cache/$1-target
  if [ -d "$d" ] && [ "$(du -s --block-size=1G "$d" | cut -f1)" -gt 20 ]; then
    echo "[run_all] $d is over 20 GB: emptied, built again from nothing" >&2
    rm -rf "$d"
  fi
  mkdir -p "$d"
  echo "$d"
}
native_target=$(cargo_target native)
export EEZYBOT_BIN_DIR=$native_target/debug

# The patched crates' checks and tests (tests/check_patches.sh: a dependency tree and
# target directory of their own), then wan/'s build (Zenoh and Cyclone DDS: about 11
# CPU-minutes from nothing, about a minute in a fresh clone with the kept directory) and
# its unit tests (ours and the patched zenoh-plugin-ros2dds'), run in the background from
# here, alongside the workspace's build and tests and the Raspberry Pi stage (whose
# OpenSSL build and emulated tests leave a core idle much of the time): started after
# them, it kept the integration tests waiting about 80 s in a fresh clone. Its output
# follows the Pi stage. tests/test_wan*.py run the WAN binaries (EEZYBOT_WAN_BIN_DIR).
wan_target=${EEZYBOT_WAN_TARGET:-$(cargo_target wan)}
[ "$wan_target" != off ] || wan_target=$PWD/wan/target  # (as before EEZYBOT_CARGO_CACHE)
export EEZYBOT_WAN_BIN_DIR=$wan_target/release
patches_log=$(mktemp)
{
  CARGO_TARGET_DIR=$(cargo_target patches) tests/check_patches.sh \
    && (cd wan && CARGO_TARGET_DIR=$wan_target cargo build --release --locked --bins --examples \
        && echo "wan/: unit tests (ours and the patched zenoh-plugin-ros2dds's)" \
        && CARGO_TARGET_DIR=$wan_target cargo test --release --locked --lib -p eezybot_wan -p zenoh-plugin-ros2dds)
} >"$patches_log" 2>&1 &
patches_pid=$!
# (stopped with its cargo if a stage before its end fails)
trap '[ -z "$patches_pid" ] || pkill -TERM -P "$patches_pid" cargo 2>/dev/null || true
      [ -z "$patches_pid" ] || kill "$patches_pid" 2>/dev/null || true
      rm -f "$patches_log"; stage ""; echo "== all stages: $SECONDS s"' EXIT
stage "firmware (avr-gcc) and its simavr harness"
make -s -C firmware/servo_control all sim
stage "cargo build"
CARGO_TARGET_DIR=$native_target cargo build --workspace --bins --examples
stage "cargo test"
CARGO_TARGET_DIR=$native_target cargo test --workspace
stage "physics twin: MuJoCo 3.17's library from PyPI's wheel (launch_scripts/install_mujoco.sh), the twin's model and physics tests on simulated time"
# (a subshell: only the twin is built against MuJoCo)
( . launch_scripts/install_mujoco.sh --env
  CARGO_TARGET_DIR=$native_target cargo test -p twin --features mujoco
  CARGO_TARGET_DIR=$native_target cargo build -p twin --features mujoco --bins )
stage "Raspberry Pi: cross-build (aarch64, profile pi-check), pure crates' tests under qemu-aarch64; alongside: the patched crates (tests/check_patches.sh), then wan/'s build and unit tests"
. launch_scripts/setup_cross.sh
pi_target=$(cargo_target pi)
# pi-check (Cargo.toml): the release's toolchain, OpenSSL and checks in less time than
# profile pi; the tests under qemu share its dependencies
CARGO_TARGET_DIR=$pi_target EEZYBOT_PI_PROFILE=pi-check launch_scripts/cross_build.sh aarch64
# the pure crates the Pi runs (servo mapping, motion limits, framing, the host link):
# their unit tests and properties, with 10 cases each under emulation (200 natively,
# above): the target's arithmetic, not a second search of the input space. Not the
# kinematics tests of what only the PC runs (IK, URDF chains, workspace envelopes:
# envelope.rs alone took 36 s under qemu), nor eezybot_msgs: its test build needs the
# whole DDS stack again, with other features than serial_node's above (about a minute
# of the stage), for CDR that cdr_encoding writes little-endian on every target.
PROPTEST_CASES=10 CARGO_TARGET_DIR=$pi_target cargo test --profile pi-check --target aarch64-unknown-linux-gnu \
  -p eezybot_kinematics -p servo_protocol --lib --test properties
stage "patched crates: resolved from patches/, and their unit tests (tests/check_patches.sh); wan/ built and its unit tests (started first)"
patches_code=0
wait "$patches_pid" || patches_code=$?
patches_pid=
cat "$patches_log"
[ "$patches_code" = 0 ] || { echo "tests/check_patches.sh, or wan/'s build or unit tests, failed (exit $patches_code)"; exit 1; }
stage "integration tests (real ROS 2)"
mkdir -p test-output
# (test-output/pytest.xml: every test's outcome and duration, for where the time went)
"$EEZYBOT_PYTHON" -m pytest tests -q -p no:cacheprovider --durations=25 --junitxml=test-output/pytest.xml "$@"
