#!/usr/bin/env bash
# Writes each patched crate's changes against its verbatim crates.io copy (the commit
# that added the copy) as a unified diff relative to the crate's root: rustdds.diff,
# ros2-client.diff, foxglove.diff. Apply upstream with `git apply` (or `patch -p1`) in the crate's repository.
# Cargo.lock is left out: ours resolve the crates for our tests here (ros2-client's points
# rustdds at ../rustdds, tests/check_patches.sh), which is no change for upstream.
set -euo pipefail
cd "$(dirname "$0")"
declare -A base=([rustdds]=090e1ae [ros2-client]=840d802 [foxglove]=cc0b52c)
for crate in "${!base[@]}"; do
  git diff --relative="patches/$crate/" "${base[$crate]}" HEAD -- "$crate" ":(exclude)$crate/Cargo.lock" > "$crate.diff"
  echo "$crate.diff: $(grep -c '^diff --git' "$crate.diff") files, $(grep -c '^[+-][^+-]' "$crate.diff") lines changed"
done
