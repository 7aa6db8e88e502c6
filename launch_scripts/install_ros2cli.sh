#!/usr/bin/env bash
# Installs the `ros2` command line with ros2_control's `ros2 control` verbs into a ROS 2
# Python venv made of the PyPI wheels: ros2cli, ros2node, ros2param, ros2_control's Python
# controller_manager module and ros2controlcli, vendored in tests/interop/ros2cli (no
# PyPI wheel of any of them exists; see its README), with their pure-Python dependencies
# pinned in tests/interop/ros2cli/requirements.txt. controller_manager_msgs must be in
# the venv already (launch_scripts/gen_control_msgs.sh).
#
#   install_ros2cli.sh VENV       install them (nothing when VENV already has them,
#                                 from the same inputs), quietly
#   install_ros2cli.sh --inputs   print the inputs' hash (setup_env.sh keys its venvs
#                                 by it; READMEs left out)
#
# The vendored files are upstream's, unchanged. Two things are done here instead: each
# package is built from a copy in a temporary directory (a build in place would leave
# build/ and *.egg-info in the repository), and controller_manager, which upstream
# installs with CMake (ament_python_install_package), gets a setup.py of our own in that
# copy: its Python package and package.xml, without the spawner scripts.
set -euo pipefail
_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_src=tests/interop/ros2cli
# in the order of their dependencies
_packages="ros2cli ros2node ros2param controller_manager ros2controlcli"

_inputs_hash() {
  ( cd "$_root" && find "$_src" -type f ! -name '*.md' ! -name '*.pyc' ! -path '*/__pycache__/*' -print0 \
      | LC_ALL=C sort -z \
      | xargs -0 sha256sum && sha256sum launch_scripts/install_ros2cli.sh ) \
    | sha256sum | cut -c1-12
}

if [ "${1:-}" = --inputs ]; then _inputs_hash; exit 0; fi
[ $# -eq 1 ] || { echo "usage: $0 VENV | --inputs" >&2; exit 2; }
venv=$(cd "$1" && pwd)

stamp="$venv/share/ros2cli/eezybot-inputs"
want="$(_inputs_hash)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then exit 0; fi

echo "[setup] installing $_packages into $venv (once)" >&2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
log="$tmp/install.log"
fail() { echo "[setup] $1 failed; the end of its log:" >&2; tail -n 40 "$log" >&2; exit 1; }

pip=("$venv/bin/pip" install -q --disable-pip-version-check)
"${pip[@]}" -r "$_root/$_src/requirements.txt" >"$log" 2>&1 || fail "pip install -r requirements.txt"

dirs=()
for pkg in $_packages; do
  cp -r "$_root/$_src/$pkg" "$tmp/$pkg"
  dirs+=("$tmp/$pkg")
done
version=$(sed -n 's|.*<version>\([^<]*\)</version>.*|\1|p' "$tmp/controller_manager/package.xml")
mkdir "$tmp/controller_manager/resource"
touch "$tmp/controller_manager/resource/controller_manager"
cat >"$tmp/controller_manager/setup.py" <<EOF
# written by launch_scripts/install_ros2cli.sh: upstream installs this package with CMake
from setuptools import setup

setup(
    name="controller_manager",
    version="$version",
    packages=["controller_manager"],
    data_files=[
        ("share/controller_manager", ["package.xml"]),
        ("share/ament_index/resource_index/packages", ["resource/controller_manager"]),
    ],
    license="Apache License, Version 2.0",
)
EOF
# --force-reinstall: a changed input keeps its version number
"${pip[@]}" --no-deps --no-build-isolation --force-reinstall "${dirs[@]}" >>"$log" 2>&1 \
  || fail "pip install of the vendored packages"

# The command and its two verbs load, from a neutral directory, with only the venv.
for verb in list_controllers switch_controllers; do
  (cd "$tmp" && env -u PYTHONPATH -u AMENT_PREFIX_PATH "$venv/bin/ros2" control "$verb" --help) >>"$log" 2>&1 \
    || fail "ros2 control $verb --help"
done
grep -q -- "--controller-manager" "$log" || fail "the check of ros2 control's help"
echo "$want" >"$stamp"
