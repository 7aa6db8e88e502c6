#!/usr/bin/env bash
# Every test of the project: Rust unit, property and doc tests, then the
# integration tests that run our real binaries against real ROS 2 (rclpy, Fast DDS,
# Cyclone DDS). Installs what it needs on first run.
set -euo pipefail
cd "$(dirname "$0")/.."
. launch_scripts/setup_env.sh
export CARGO_TERM_QUIET=true
echo "== firmware (avr-gcc) and its simavr harness"
make -s -C firmware/servo_control all sim
echo "== cargo build"
cargo build --workspace --bins --examples
echo "== cargo test"
cargo test --workspace
echo "== patched crates: resolved from patches/, and their unit tests (tests/check_patches.sh)"
tests/check_patches.sh
echo "== Raspberry Pi: cross-build (aarch64, profile pi), pure crates' tests under qemu-aarch64"
. launch_scripts/setup_cross.sh
launch_scripts/cross_build.sh aarch64
# the IK properties with 25 cases each under emulation (200 natively, above)
PROPTEST_CASES=25 cargo test --target aarch64-unknown-linux-gnu -p eezybot_kinematics -p servo_protocol -p eezybot_msgs
echo "== integration tests (real ROS 2)"
"$EEZYBOT_PYTHON" -m pytest tests -q -p no:cacheprovider --durations=15 "$@"
