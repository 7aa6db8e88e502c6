#!/usr/bin/env bash
# Installs MuJoCo for the physics twin (nodes/twin), idempotently and quietly, and
# prints the directory of its library (for MUJOCO_DYNAMIC_LINK_DIR and LD_LIBRARY_PATH).
#
#   launch_scripts/install_mujoco.sh            # install if missing, print the lib dir
#   . launch_scripts/install_mujoco.sh --env    # also export MUJOCO_DYNAMIC_LINK_DIR,
#                                               # LD_LIBRARY_PATH and MUJOCO_GL
#
# Which MuJoCo: the library inside PyPI's wheel `mujoco==3.17.0`, pinned by its hash.
# The Rust bindings (mujoco-rs 7.0.0+mj-3.17.0) are generated for exactly that version,
# and Debian's libmujoco-dev is 2.2.2, four years and an incompatible API older. The
# wheel is only unpacked: no Python is involved at run time. For the twin's camera, the
# Debian packages of Mesa's EGL (offscreen OpenGL on the CPU, no display needed).
# (strict mode only when run: a sourcing shell keeps its own options)
[ "${BASH_SOURCE[0]}" != "$0" ] || set -euo pipefail
_here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_mj_version=3.17.0
# sha256 of mujoco-3.17.0-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl
_mj_sha256=d66928d86a2d1b601bbaa4dc11db50214d17d5301bb8afd84721313b67ff0874

_mj_install() {
  local cache dir wheel tmp
  cache="${XDG_CACHE_HOME:-$HOME/.cache}/eezybot"
  dir="$cache/mujoco-$_mj_version"
  . "$_here/launch_scripts/apt_missing.sh"
  apt_missing mujoco libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1
  if [ ! -f "$dir/.complete" ]; then
    case "$(uname -m)" in
      x86_64) ;;
      *) echo "[mujoco] the pinned MuJoCo wheel is for x86_64; this is $(uname -m)" >&2; return 1 ;;
    esac
    mkdir -p "$cache"
    (
      flock 9
      if [ ! -f "$dir/.complete" ]; then
        echo "[mujoco] installing MuJoCo $_mj_version's library from PyPI's wheel into $dir (once)" >&2
        tmp=$(mktemp -d)
        trap 'rm -rf "$tmp"' EXIT
        python3 -m pip download -q --disable-pip-version-check --no-deps --only-binary=:all: \
          --python-version 3.11 --platform manylinux_2_28_x86_64 "mujoco==$_mj_version" -d "$tmp" >&2
        wheel=$(ls "$tmp"/mujoco-"$_mj_version"-*.whl)
        if [ "$(sha256sum "$wheel" | cut -d' ' -f1)" != "$_mj_sha256" ]; then
          echo "[mujoco] $wheel does not have the pinned sha256 $_mj_sha256" >&2
          exit 1
        fi
        rm -rf "$dir"
        mkdir -p "$dir/lib"
        python3 -c 'import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extract(sys.argv[2], sys.argv[3])' \
          "$wheel" "mujoco/libmujoco.so.$_mj_version" "$tmp/x"
        mv "$tmp/x/mujoco/libmujoco.so.$_mj_version" "$dir/lib/"
        ln -s "libmujoco.so.$_mj_version" "$dir/lib/libmujoco.so"
        touch "$dir/.complete"
      fi
    ) 9>"$dir.lock"
  fi
  echo "$dir/lib"
}

if [ "${1:-}" = --env ]; then
  MUJOCO_DYNAMIC_LINK_DIR=$(_mj_install)
  export MUJOCO_DYNAMIC_LINK_DIR
  export LD_LIBRARY_PATH="$MUJOCO_DYNAMIC_LINK_DIR${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  export MUJOCO_GL=egl
else
  _mj_install
fi
