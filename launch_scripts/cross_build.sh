#!/usr/bin/env bash
# Cross-builds the Raspberry Pi half of the graph (serial_node, virtual_arduino and
# camera_node) on this PC, so the Pi needs no Rust toolchain:
#
#   launch_scripts/cross_build.sh [aarch64|armv7|all] [--wan]     (default all)
#
#   aarch64: aarch64-unknown-linux-gnu, 64-bit Raspberry Pi OS / Ubuntu (Pi 3, 4, 5, Zero 2 W)
#   armv7:   armv7-unknown-linux-gnueabihf, 32-bit Raspberry Pi OS (Pi 2, 3, 4, Zero 2 W)
#
# Installs what it needs (launch_scripts/setup_cross.sh), builds with the `pi` profile of
# Cargo.toml (stripped, LTO; EEZYBOT_PI_PROFILE=pi-check: the test command's quicker
# check build, not for the Pi) and DDS Security (SROS2) built in: OpenSSL is compiled from
# source for the target and linked statically (feature ros_plumbing/vendored-openssl), so
# the Pi needs no libssl and this PC no target libssl; its build is kept in
# ~/.cache/eezybot/openssl for the next cross-build (EEZYBOT_OPENSSL_CACHE: another
# directory, or off). Checks that the binaries start (under qemu-user), and writes per
# target a bundle dist/eezybot-pi-ARCH/ and its tarball dist/eezybot-pi-ARCH.tar.gz:
# bin/, launch_scripts/{lib.sh,pi.sh}, deploy/ (systemd unit, udev rule, install.sh),
# README.txt and raspberry_pi.md. Copy the tarball to the Pi, unpack it and follow
# README.txt (docs/raspberry_pi.md).
#
# --wan (any position; opt-in): also builds the WAN bridge eezybot_wan_bridge from wan/
# (its release profile, target dir wan/target/TRIPLE/release) and puts it in the bundle's
# bin/, where pi.sh finds it (ZENOH_ROUTER set: wan/README.md). Needs cmake, libclang-dev
# and the cross g++ (Cyclone DDS is built from source; setup_cross.sh installs them with
# EEZYBOT_CROSS_WAN=1); the first build takes about 10 CPU-minutes per target.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

_say() { echo "[cross_build] $*" >&2; }

# --wan anywhere; the other arguments as without it.
wan=0
args=()
for a in "$@"; do
  if [ "$a" = --wan ]; then wan=1; else args+=("$a"); fi
done
set -- "${args[@]}"

case "${1:-all}" in
  aarch64) arches=(aarch64) ;;
  armv7) arches=(armv7) ;;
  all) arches=(aarch64 armv7) ;;
  -h|--help) sed -n '2,28s/^# \{0,1\}//p' "$0"; exit 0 ;;
  *) _say "unknown target '$1': aarch64, armv7 or all"; exit 2 ;;
esac
[ $# -le 1 ] || { _say "one argument at most: aarch64, armv7 or all"; exit 2; }

triple() {
  case "$1" in
    aarch64) echo aarch64-unknown-linux-gnu ;;
    armv7) echo armv7-unknown-linux-gnueabihf ;;
  esac
}
# The binutils prefix of the cross toolchain.
tools() {
  case "$1" in
    aarch64) echo aarch64-linux-gnu ;;
    armv7) echo arm-linux-gnueabihf ;;
  esac
}
# The C cross compiler and archiver: openssl-src (OpenSSL's own build, with perl and
# make) and ring's C and assembly use them through the cc crate.
cc_of() { echo "$(tools "$1")-gcc"; }
ar_of() { echo "$(tools "$1")-ar"; }
# The cargo runner of .cargo/config.toml, for the start-up check.
qemu() {
  case "$1" in
    aarch64) echo "qemu-aarch64 -L /usr/aarch64-linux-gnu" ;;
    armv7) echo "qemu-arm -L /usr/arm-linux-gnueabihf" ;;
  esac
}

[ "$wan" = 0 ] || export EEZYBOT_CROSS_WAN=1  # setup_cross.sh: cmake, libclang, cross g++
. launch_scripts/setup_cross.sh

bins=(serial_node virtual_arduino camera_node)
profile=${EEZYBOT_PI_PROFILE:-pi}
case "$profile" in
  pi) built_as="profile pi (release: fat LTO, stripped)" ;;
  pi-check) built_as="profile pi-check (the test command's check build: NOT optimised for the Pi; build the release with launch_scripts/cross_build.sh)" ;;
  *) _say "EEZYBOT_PI_PROFILE=$profile: pi or pi-check"; exit 2 ;;
esac
version=$(git describe --always --dirty 2>/dev/null || echo unknown)
# cargo's target directory (CARGO_TARGET_DIR: tests/run_all.sh keeps the Pi's build per
# machine), absolute
target_dir=$(realpath -m "${CARGO_TARGET_DIR:-target}")
declare -A need_glibc bridge_glibc
mkdir -p dist
for arch in "${arches[@]}"; do
  t=$(triple "$arch")
  T=$(tr 'a-z-' 'A-Z_' <<<"$t")
  # OpenSSL's own build (openssl-src, about 2 minutes on 2 cores) is kept per machine,
  # outside target/, for this OpenSSL release, target, profile and cross compiler:
  # openssl-sys links the kept one (<TRIPLE>_OPENSSL_DIR, static) instead of building
  # it again. EEZYBOT_OPENSSL_CACHE=off builds it every time.
  openssl_version=$(awk '/^name = "openssl-src"$/ { getline; gsub(/"/, "", $3); print $3 }' Cargo.lock)
  compiler=$("$(cc_of "$arch")" --version | head -1 | cksum | cut -d' ' -f1)
  openssl_cache=${EEZYBOT_OPENSSL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/eezybot/openssl}
  openssl_kept=$openssl_cache/$openssl_version-$t-$profile-$compiler
  openssl_env=()
  if [ "$openssl_cache" != off ] && [ -f "$openssl_kept/lib/libssl.a" ]; then
    openssl_env=("${T}_OPENSSL_NO_VENDOR=1" "${T}_OPENSSL_DIR=$openssl_kept" "${T}_OPENSSL_STATIC=1")
    _say "building ${bins[*]} for $t (profile $profile, with DDS Security; OpenSSL $openssl_version built before, kept in $openssl_kept)"
  else
    _say "building ${bins[*]} for $t (profile $profile, with DDS Security; the first build takes several minutes, OpenSSL among them)"
  fi
  # CC_<triple>/AR_<triple>: what the cc crate would guess for these triples, said
  # explicitly, so OpenSSL is never configured with the host's gcc
  env "CC_${t//-/_}=$(cc_of "$arch")" "AR_${t//-/_}=$(ar_of "$arch")" "${openssl_env[@]}" \
    cargo build -q --profile "$profile" --target "$t" -p serial_node -p camera_node --bins --features ros_plumbing/vendored-openssl
  out="$target_dir/$t/$profile"
  if [ "$openssl_cache" != off ] && [ ${#openssl_env[@]} = 0 ]; then
    for built in "$out"/build/openssl-sys-*/out/openssl-build/install; do
      [ -f "$built/lib/libssl.a" ] || continue
      mkdir -p "$openssl_cache"
      tmp=$(mktemp -d "$openssl_cache/.new.XXXXXX")
      cp -a "$built/include" "$built/lib" "$tmp/"
      mv -T "$tmp" "$openssl_kept" 2>/dev/null || rm -rf "$tmp"  # another build kept it first
      break
    done
  fi

  # The binaries start on the target's CPU and name no file of this build tree.
  if ! help=$($(qemu "$arch") "$out/serial_node" --help 2>&1) || ! grep -q "^serial_node" <<<"$help"; then
    _say "$out/serial_node --help under qemu: $help"; exit 1
  fi
  if ! help=$($(qemu "$arch") "$out/camera_node" --help 2>&1) || ! grep -q "^camera_node" <<<"$help"; then
    _say "$out/camera_node --help under qemu: $help"; exit 1
  fi
  code=0; $(qemu "$arch") "$out/virtual_arduino" 2>/dev/null || code=$?
  [ "$code" = 2 ] || { _say "$out/virtual_arduino under qemu exited $code, not 2 (usage)"; exit 1; }
  # One exception: OpenSSL compiles in the default directories of its dynamic engines and
  # providers (ENGINESDIR, MODULESDIR), under its install prefix in this build tree. They
  # are read only if an engine or provider module is loaded by name (none is: the
  # providers are built in, and OPENSSL_ENGINES/OPENSSL_MODULES would override them).
  root_re=$(printf '%s' "$root" | sed 's/[][\.*^$+?(){}|/]/\\&/g')
  target_re=$(printf '%s' "$target_dir" | sed 's/[][\.*^$+?(){}|/]/\\&/g')
  openssl_dirs="^$target_re/$t/$profile/build/openssl-sys-[0-9a-f]+/out/openssl-build/install/lib/(engines-3|ossl-modules)\$"
  for b in "${bins[@]}"; do
    leaks=$(grep -aoE "($root_re|$target_re)/[[:print:]]*" "$out/$b" | grep -vE "$openssl_dirs" | sort -u || true)
    if [ -n "$leaks" ]; then
      _say "$out/$b names a path in $root or $target_dir:"; echo "$leaks" >&2; exit 1
    fi
  done

  # --wan: the WAN bridge, from wan/ (its own workspace and Cargo.lock; its release
  # profile, stripped). cyclors' build script builds Cyclone DDS with the cmake crate, which
  # sets CMAKE_SYSTEM_NAME/PROCESSOR itself for a cross target and takes the compilers from
  # the cc crate (CC_/CXX_<triple>: the cross gcc and g++, said explicitly as above), then
  # runs bindgen, which passes the target to libclang: clang finds the target's headers in
  # /usr/TOOLS itself (the bindings say __SIZEOF_PTHREAD_MUTEX_T 48, aarch64's, not the
  # host's 40). The linker and runner: .cargo/config.toml (found from wan/ too).
  # Cyclone DDS is built with DDS Security (wan/Cargo.toml: SROS2 on the Pi's LAN with the
  # bridge): its cmake finds OpenSSL for the target (OPENSSL_ROOT_DIR) and openssl-sys
  # links it statically, both the OpenSSL built for the Pi above (kept, or in this build's
  # tree), so the bridge needs no libssl on the Pi either.
  bridge=()
  if [ "$wan" = 1 ]; then
    ssl=$openssl_kept
    [ -f "$ssl/lib/libssl.a" ] || ssl=$(dirname "$(find "$out"/build/openssl-sys-*/out/openssl-build/install/lib \
      -name libssl.a -print -quit 2>/dev/null)")/..
    [ -f "$ssl/lib/libssl.a" ] || { _say "no OpenSSL built for $t (expected in $openssl_kept or $out/build)"; exit 1; }
    _say "building eezybot_wan_bridge for $t (wan/, release, DDS Security with OpenSSL from $ssl; the first build takes about 10 CPU-minutes: Zenoh, Cyclone DDS)"
    (cd wan && env "CC_${t//-/_}=$(cc_of "$arch")" "CXX_${t//-/_}=$(tools "$arch")-g++" "AR_${t//-/_}=$(ar_of "$arch")" \
      "${T}_OPENSSL_NO_VENDOR=1" "${T}_OPENSSL_DIR=$ssl" "${T}_OPENSSL_STATIC=1" "OPENSSL_ROOT_DIR=$ssl" \
      cargo build -q --release --target "$t" --target-dir target --bin eezybot_wan_bridge)
    bridge=("wan/target/$t/release/eezybot_wan_bridge")
    # It starts on the target's CPU (qemu-user cannot open its DDS sockets: the
    # configuration only), needs no shared library but glibc's, and names no path of
    # this build tree.
    if ! config=$($(qemu "$arch") "${bridge[0]}" pi --router tcp/10.0.0.1:7447 --print-config 2>/dev/null) \
      || ! grep -q '"nodename":"eezybot_wan_bridge_pi"' <<<"$config"; then
      _say "${bridge[0]} pi --print-config under qemu: $config"; exit 1
    fi
    needed=$("$(tools "$arch")-objdump" -p "${bridge[0]}" | awk '$1 == "NEEDED" { print $2 }')
    if grep -vqE '^(libc|libm|libdl|libpthread|librt|libgcc_s|ld-linux[-a-z0-9]*)\.so' <<<"$needed"; then
      _say "${bridge[0]} needs a shared library that is not glibc's:"; echo "$needed" >&2; exit 1
    fi
    leaks=$(grep -aoE "$root_re/[[:print:]]*" "${bridge[0]}" | sort -u || true)
    if [ -n "$leaks" ]; then
      _say "${bridge[0]} names a path in $root:"; echo "$leaks" >&2; exit 1
    fi
    bridge_glibc[$arch]=$("$(tools "$arch")-objdump" -T "${bridge[0]}" \
      | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -uV | tail -1)
  fi

  # The newest glibc symbol version the binaries use: the oldest OS they run on.
  glibc=$(for f in "${bins[@]/#/$out/}" "${bridge[@]}"; do "$(tools "$arch")-objdump" -T "$f"; done \
    | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -uV | tail -1)
  need_glibc[$arch]=$glibc

  name="eezybot-pi-$arch"
  bundle="dist/$name"
  rm -rf "$bundle" "$bundle.tar.gz"
  mkdir -p "$bundle/bin" "$bundle/launch_scripts"
  for b in "${bins[@]}"; do install -m 0755 "$out/$b" "$bundle/bin/$b"; done
  [ "$wan" = 0 ] || install -m 0755 "${bridge[0]}" "$bundle/bin/eezybot_wan_bridge"
  install -m 0644 launch_scripts/lib.sh "$bundle/launch_scripts/lib.sh"
  install -m 0755 launch_scripts/pi.sh "$bundle/launch_scripts/pi.sh"
  cp -r deploy "$bundle/deploy"
  install -m 0644 docs/raspberry_pi.md "$bundle/raspberry_pi.md"
  cat >"$bundle/README.txt" <<EOF
EezyBot teleop: the Raspberry Pi half (serial_node, camera_node), prebuilt for $t
(version $version, $built_as). No Rust toolchain is needed on the Pi; the binaries need glibc
$glibc or later (\`ldd --version\`: Raspberry Pi OS bookworm, Ubuntu 22.04 and later).

  bin/serial_node        the ROS 2 node that drives the Arduino over USB serial; DDS
                         Security (SROS2) is built in, OpenSSL linked statically: no
                         libssl needed. Off unless ROS_SECURITY_ENABLE=true: install
                         the Pi's enclave with deploy/install.sh --keystore DIR
                         (raspberry_pi.md, "SROS2: the Pi's enclave")
  bin/virtual_arduino    a virtual Arduino behind a pseudo-terminal (tests without a board)
  bin/camera_node        a V4L2 webcam as camera/image_raw/compressed (JPEG) and
                         camera/camera_info (raspberry_pi.md, "6. A camera"; not started by
                         pi.sh: bin/camera_node --ros-args -p device:=/dev/video0)
  launch_scripts/pi.sh   starts serial_node (SERIAL_PORT, ROS_DOMAIN_ID; Ctrl-C stops it)
  deploy/                systemd unit, udev rule (/dev/eezybot), env file, install.sh

Try it by hand (as a user in the dialout group):

  ROS_DOMAIN_ID=0 launch_scripts/pi.sh                  # Arduino on /dev/eezybot or /dev/ttyACM0
  SERIAL_PORT=mock launch_scripts/pi.sh                 # the built-in virtual Arduino

Install as a service that starts at boot (to /opt/eezybot; user eezybot, group dialout):

  sudo deploy/install.sh                # again after an update; --uninstall removes it
  sudoedit /etc/default/eezybot         # ROS_DOMAIN_ID, SERIAL_PORT, EEZYBOT_ROS_ARGS
  sudo systemctl restart eezybot-serial
  journalctl -u eezybot-serial -f

The PC runs launch_scripts/pc.sh in the same ROS_DOMAIN_ID, on a network that passes
UDP multicast. Firewall ports, Wi-Fi and troubleshooting: raspberry_pi.md (here and
in docs/ of the source tree).
EOF
  [ "$wan" = 0 ] || cat >>"$bundle/README.txt" <<EOF

Across the internet (the PC and the Pi on different networks): bin/eezybot_wan_bridge,
the Pi's side of the WAN bridge (a Zenoh client of eezybot_wan_router, with
zenoh-plugin-ros2dds and Cyclone DDS built in; needs glibc ${bridge_glibc[$arch]} or later).
pi.sh starts it beside serial_node when ZENOH_ROUTER is set (tls/HOST:PORT of the
router); ZENOH_TLS_DIR holds ca.pem, pi.pem and pi.key (launch_scripts/wan_certs.sh on
the PC makes them). raspberry_pi.md, "The WAN bridge". With SROS2 on as well
(ROS_SECURITY_ENABLE=true), the bridge joins the Pi's secured LAN under its own enclave,
/eezybot/bridge_pi, of the same keystore (DDS Security built in, OpenSSL linked
statically): install it beside the Pi's,
  sudo deploy/install.sh --keystore DIR --enclave /eezybot/bridge_pi
EOF
  tar -C dist --owner=0 --group=0 -czf "$bundle.tar.gz" "$name"
done

_say "stripped binaries:"
for arch in "${arches[@]}"; do
  t=$(triple "$arch")
  for b in "${bins[@]}"; do
    printf '  %-30s %-16s %6s KiB\n' "$t" "$b" $(( $(stat -c %s "$target_dir/$t/$profile/$b") / 1024 )) >&2
  done
  if [ "$wan" = 1 ]; then
    printf '  %-30s %-16s %6s KiB  (needs glibc >= %s)\n' "$t" eezybot_wan_bridge \
      $(( $(stat -c %s "wan/target/$t/release/eezybot_wan_bridge") / 1024 )) "${bridge_glibc[$arch]}" >&2
  fi
  printf '  %-47s %6s KiB  (needs glibc >= %s)\n' "dist/eezybot-pi-$arch.tar.gz" \
    $(( $(stat -c %s "dist/eezybot-pi-$arch.tar.gz") / 1024 )) "${need_glibc[$arch]}" >&2
done
