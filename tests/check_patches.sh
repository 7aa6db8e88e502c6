#!/usr/bin/env bash
# The patched crates of patches/ stay honest (tests/run_all.sh runs this):
# 1. the workspace resolves rustdds, ros2-client and foxglove to their copies under patches/, and
#    wan/ zenoh-plugin-ros2dds and zenoh-link-tls to wan/patches/
#    (cargo only warns when a [patch.crates-io] entry goes unused, e.g. after a
#    version bump), and so does patches/ros2-client's own lock file when its tests
#    run against the patched rustdds;
# 2. the unit tests of both copies pass, as we build them (feature `security`),
#    ros2-client's against the patched rustdds. (foxglove's copy is tested through
#    libs/foxglove_bridge, its only user: its own tests need a dozen more crates.)
# Both crates build in one target directory of their own (CARGO_TARGET_DIR, default
# target/patches; tests/run_all.sh keeps it per machine): their dependencies are shared
# between the two, not with the workspace (other profile).
# `--no-tests` runs only the resolution checks.
set -euo pipefail
cd "$(dirname "$0")/.."
python=${EEZYBOT_PYTHON:-python3}
patch_rustdds=(--config 'patch.crates-io.rustdds.path="patches/rustdds"')

# $1: what is checked; the rest: package=directory pairs; stdin: cargo metadata's JSON
check_resolution() {
  local what=$1
  shift
  "$python" -c "$resolution_py" "$what" "$@"
}
resolution_py=$(cat <<'PY'
import json, os, sys
what, wanted = sys.argv[1], sys.argv[2:]
metadata = json.load(sys.stdin)
bad = []
for pair in wanted:
    name, directory = pair.split("=")
    want = os.path.realpath(os.path.join(directory, "Cargo.toml"))
    found = [os.path.realpath(p["manifest_path"]) for p in metadata["packages"] if p["name"] == name]
    if found != [want]:
        bad.append(f"{name} resolves to {found or 'nothing'}, not {want}")
if bad:
    sys.exit(f"{what}: " + "; ".join(bad) + "\n(a [patch.crates-io] entry goes unused when the "
             "locked version differs from the patch's version: cargo update -p <crate>)")
print(f"{what}: " + ", ".join(p.split("=")[0] for p in wanted) + " resolve to patches/")
PY
)

metadata=$(mktemp)
trap 'rm -f "$metadata"' EXIT
# --locked: a lock file that would have to change (e.g. to record an unused patch)
# fails here too
cargo metadata --format-version 1 --locked >"$metadata"
check_resolution "workspace (Cargo.lock)" rustdds=patches/rustdds ros2-client=patches/ros2-client \
  foxglove=patches/foxglove <"$metadata"
cargo metadata --format-version 1 --locked --manifest-path patches/ros2-client/Cargo.toml \
  "${patch_rustdds[@]}" >"$metadata"
check_resolution "patches/ros2-client (its Cargo.lock)" rustdds=patches/rustdds <"$metadata"
# wan/ (its own workspace): the copies of the Zenoh plugin and TLS link; their fixes are
# tested through the bridges (tests/test_wan.py: no duplicate after restarts; no session
# ends over an impaired WAN)
cargo metadata --format-version 1 --locked --manifest-path wan/Cargo.toml >"$metadata"
check_resolution "wan (wan/Cargo.lock)" zenoh-plugin-ros2dds=wan/patches/zenoh-plugin-ros2dds \
  zenoh-link-tls=wan/patches/zenoh-link-tls <"$metadata"

[[ ${1:-} == --no-tests ]] && exit 0
# debug info as the workspace has it (line tables, none for dependencies): smaller
# and quicker to build than the crates' default
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$PWD/target/patches}
profile=(--config 'profile.dev.debug="line-tables-only"' --config 'profile.dev.package."*".debug=false')
cargo test --locked --manifest-path patches/rustdds/Cargo.toml "${profile[@]}" --features security --lib
cargo test --locked --manifest-path patches/ros2-client/Cargo.toml "${profile[@]}" "${patch_rustdds[@]}" \
  --features security --lib
