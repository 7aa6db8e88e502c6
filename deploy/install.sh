#!/usr/bin/env bash
# Installs this bundle (from launch_scripts/cross_build.sh) on a Raspberry Pi as a service
# that starts serial_node at boot. Run as root from the unpacked bundle; safe to repeat
# (an update: unpack the new bundle, run it again).
#
#   sudo deploy/install.sh               install or update, then (re)start the service
#   sudo deploy/install.sh --keystore DIR   SROS2: install the Pi's enclave, turn security on
#   sudo deploy/install.sh --uninstall   stop and remove it (keeps /etc/default/eezybot and
#                                        /etc/eezybot/keystore)
#
# What it does:
#   /opt/eezybot/                          bin/, launch_scripts/, deploy/, README.txt, docs
#   user and group eezybot (system user, no login), member of dialout
#   /etc/udev/rules.d/99-eezybot.rules     /dev/eezybot for the Arduino; reloads udev
#   /etc/default/eezybot                   from deploy/eezybot.env.example, only if absent
#   /etc/systemd/system/eezybot-serial.service, enabled and (re)started
#
# --keystore DIR [--enclave /eezybot/pi]: DIR is a copy of the PC's keystore holding
# enclaves/eezybot/pi (made by launch_scripts/keystore.sh, copied with its links
# resolved, README: Securing the link), or that enclave directory itself. Its six files
# are checked (the certificate issued by identity_ca.cert.pem and matching key.pem), then
# copied to /etc/eezybot/keystore/enclaves/eezybot/pi, owner eezybot, directories 0700,
# key.pem 0400, the rest 0444; ROS_SECURITY_ENABLE=true, ROS_SECURITY_STRATEGY=Enforce and
# ROS_SECURITY_KEYSTORE=/etc/eezybot/keystore are set in /etc/default/eezybot; a running
# service is restarted. DESTDIR=/some/root installs under that root instead (no restart).
set -euo pipefail

PREFIX=/opt/eezybot
USER_NAME=eezybot
UNIT=eezybot-serial.service
UNIT_PATH=/etc/systemd/system/$UNIT
RULES_PATH=/etc/udev/rules.d/99-eezybot.rules
ENV_PATH=/etc/default/eezybot
KEYSTORE_PATH=/etc/eezybot/keystore
ENCLAVE_FILES="cert.pem key.pem identity_ca.cert.pem permissions_ca.cert.pem governance.p7s permissions.p7s"
DESTDIR=${DESTDIR:-}

bundle="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_say() { echo "[install] $*" >&2; }

systemd_running() { [ -d /run/systemd/system ]; }
udev_running() { command -v udevadm >/dev/null 2>&1 && [ -e /run/udev/control ]; }

reload_udev() {
  if udev_running; then
    udevadm control --reload-rules
    udevadm trigger --subsystem-match=tty
  else
    _say "udev is not running here: the rule applies from the next boot"
  fi
}

uninstall() {
  if [ -e "$UNIT_PATH" ]; then
    if systemd_running; then
      systemctl disable --now --quiet "$UNIT" || true
    else
      systemctl disable --quiet "$UNIT" 2>/dev/null || true
    fi
    rm -f "$UNIT_PATH"
    ! systemd_running || systemctl daemon-reload
  fi
  if [ -e "$RULES_PATH" ]; then
    rm -f "$RULES_PATH"
    reload_udev
  fi
  rm -rf "$PREFIX" "$PREFIX.new" "$PREFIX.old"
  if id -u "$USER_NAME" >/dev/null 2>&1; then
    userdel "$USER_NAME"
  fi
  if [ -d "$KEYSTORE_PATH" ]; then
    _say "removed (kept $ENV_PATH and the keystore $KEYSTORE_PATH; delete them by hand if you want: sudo rm -r $KEYSTORE_PATH)"
  else
    _say "removed (kept $ENV_PATH; delete it by hand if you want)"
  fi
}

ensure_user() {
  # An unprivileged system user that may open the serial port.
  if ! id -u "$USER_NAME" >/dev/null 2>&1; then
    useradd --system --user-group --no-create-home --home-dir /nonexistent \
      --shell /usr/sbin/nologin --comment "EezyBot serial_node" "$USER_NAME"
  fi
  usermod -a -G dialout "$USER_NAME"
}

# set_env NAME VALUE: in the environment file, replace the line NAME=... (or a commented
# #NAME=...) by NAME=VALUE, or append it.
set_env() {
  local file="$DESTDIR$ENV_PATH" tmp
  if grep -qE "^#? *$1=" "$file"; then
    tmp=$(mktemp "$file.XXXXXX")
    sed -E "s|^#? *$1=.*|$1=$2|" "$file" >"$tmp"
    chmod 0644 "$tmp"
    mv "$tmp" "$file"
  else
    echo "$1=$2" >>"$file"
  fi
}

# install_keystore DIR ENCLAVE: the enclave's six files, checked, to KEYSTORE_PATH.
install_keystore() {
  local src=$1 enclave=$2 f dst new a b
  [[ $enclave =~ ^(/[A-Za-z_][A-Za-z0-9_]*)+$ ]] || { _say "--enclave $enclave: an enclave path such as /eezybot/pi"; exit 2; }
  [ -d "$src" ] || { _say "--keystore $src is not a directory"; exit 2; }
  if [ ! -e "$src/cert.pem" ] && [ -d "$src/enclaves/${enclave#/}" ]; then
    src="$src/enclaves/${enclave#/}"
  fi
  for f in $ENCLAVE_FILES; do
    [ -f "$src/$f" ] && [ -r "$src/$f" ] || {
      _say "$src/$f is missing (or a link whose target was not copied: copy with rsync -L / scp -r, README: Securing the link)"
      exit 1
    }
  done
  if command -v openssl >/dev/null 2>&1; then
    openssl verify -no_check_time -CAfile "$src/identity_ca.cert.pem" "$src/cert.pem" >/dev/null 2>&1 || {
      _say "$src/cert.pem is not issued by $src/identity_ca.cert.pem (an enclave of another keystore?)"
      exit 1
    }
    # Not valid now: most often this Pi's clock (no RTC: NTP sets it after boot).
    openssl verify -CAfile "$src/identity_ca.cert.pem" "$src/cert.pem" >/dev/null 2>&1 ||
      _say "WARNING: $src/cert.pem is not valid at this clock ($(date -u)): $(openssl x509 -noout -dates -in "$src/cert.pem" | tr '\n' ' ')- check the clock (timedatectl) before starting"
    a=$(openssl x509 -noout -pubkey -in "$src/cert.pem" 2>/dev/null)
    b=$(openssl pkey -pubout -in "$src/key.pem" 2>/dev/null) || b=""
    [ -n "$a" ] && [ "$a" = "$b" ] || { _say "$src/key.pem is not the key of $src/cert.pem"; exit 1; }
    openssl x509 -noout -subject -nameopt RFC2253 -in "$src/cert.pem" | grep -qx "subject=CN=$enclave" || {
      _say "$src/cert.pem is not the certificate of $enclave: $(openssl x509 -noout -subject -in "$src/cert.pem")"
      exit 1
    }
  fi
  [ -n "$DESTDIR" ] || ensure_user
  dst="$DESTDIR$KEYSTORE_PATH/enclaves/${enclave#/}"
  new="$dst.new"
  rm -rf "$new"
  mkdir -p "$new"
  for f in $ENCLAVE_FILES; do
    cp -L "$src/$f" "$new/$f"
  done
  # the unsigned permissions too, when there, to read what the enclave may do
  [ ! -f "$src/permissions.xml" ] || cp -L "$src/permissions.xml" "$new/permissions.xml"
  chmod 0444 "$new"/*
  chmod 0400 "$new/key.pem"
  chmod 0700 "$new"
  rm -rf "$dst.old"
  [ ! -e "$dst" ] || mv "$dst" "$dst.old"
  mv "$new" "$dst"
  rm -rf "$dst.old"
  # every directory from the keystore down to the enclave: owner-only
  f="$dst"
  while [ "$f" != "$DESTDIR$KEYSTORE_PATH" ] && [ "$f" != / ]; do
    f=$(dirname "$f")
    chmod 0700 "$f"
  done
  if id -u "$USER_NAME" >/dev/null 2>&1; then
    chown -R "$USER_NAME:$USER_NAME" "$DESTDIR$KEYSTORE_PATH"
  else
    _say "no user $USER_NAME here (DESTDIR install): the keystore stays owned by $(id -un)"
  fi

  mkdir -p "$(dirname "$DESTDIR$ENV_PATH")"
  if [ ! -e "$DESTDIR$ENV_PATH" ]; then
    if [ -f "$bundle/deploy/eezybot.env.example" ]; then
      install -m 0644 "$bundle/deploy/eezybot.env.example" "$DESTDIR$ENV_PATH"
    else
      install -m 0644 /dev/null "$DESTDIR$ENV_PATH"
    fi
  fi
  set_env ROS_SECURITY_ENABLE true
  set_env ROS_SECURITY_STRATEGY Enforce
  set_env ROS_SECURITY_KEYSTORE "$KEYSTORE_PATH"
  _say "enclave $enclave installed in $KEYSTORE_PATH (owner $(stat -c %U "$dst"), key.pem 0400, directories 0700); security on in $ENV_PATH:"
  _say "  ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce ROS_SECURITY_KEYSTORE=$KEYSTORE_PATH"
  _say "certificate valid $(openssl x509 -noout -startdate -in "$dst/cert.pem" 2>/dev/null | cut -d= -f2) ... $(openssl x509 -noout -enddate -in "$dst/cert.pem" 2>/dev/null | cut -d= -f2); this clock: $(date -u)"
  if [ -z "$DESTDIR" ] && systemd_running && systemctl is-enabled --quiet "$UNIT" 2>/dev/null; then
    systemctl restart "$UNIT"
    _say "$UNIT restarted: $(systemctl is-active "$UNIT" || true) (journalctl -u ${UNIT%.service} -f)"
  fi
}

install_bundle() {
  local out
  for f in bin/serial_node launch_scripts/pi.sh launch_scripts/lib.sh deploy/$UNIT deploy/99-eezybot.rules deploy/eezybot.env.example; do
    [ -e "$bundle/$f" ] || { _say "$bundle/$f is missing: run this from an unpacked bundle (cross_build.sh)"; exit 1; }
  done
  # The binaries must be built for this OS: aarch64 for a 64-bit one, armv7 for 32-bit,
  # and need glibc 2.34 or later (Raspberry Pi OS bookworm, Ubuntu 22.04).
  if ! out=$("$bundle/bin/serial_node" --help 2>&1); then
    _say "bin/serial_node does not run here: $(head -c 300 <<<"$out")"
    _say "this OS: $(uname -m), $(ldd --version 2>/dev/null | head -1)"
    _say "use eezybot-pi-aarch64 on a 64-bit OS (uname -m: aarch64), eezybot-pi-armv7 on a 32-bit one (armv7l)"
    exit 1
  fi

  ensure_user

  # The files: into a fresh directory, then swapped in, so a running node keeps its binary
  # and an interrupted install leaves the old one in place.
  if [ "$bundle" != "$PREFIX" ]; then
    rm -rf "$PREFIX.new" "$PREFIX.old"
    mkdir -p "$PREFIX.new"
    cp -r "$bundle/bin" "$bundle/launch_scripts" "$bundle/deploy" "$PREFIX.new/"
    for f in README.txt raspberry_pi.md; do
      [ ! -e "$bundle/$f" ] || cp "$bundle/$f" "$PREFIX.new/"
    done
    chown -R root:root "$PREFIX.new"
    chmod -R u=rwX,go=rX "$PREFIX.new"
    [ ! -e "$PREFIX" ] || mv "$PREFIX" "$PREFIX.old"
    mv "$PREFIX.new" "$PREFIX"
    rm -rf "$PREFIX.old"
  fi

  if [ ! -e "$ENV_PATH" ]; then
    install -m 0644 "$bundle/deploy/eezybot.env.example" "$ENV_PATH"
    _say "wrote $ENV_PATH (ROS_DOMAIN_ID=0): edit it to match the PC"
  fi
  # The unit before the udev rule: the rule's SYSTEMD_WANTS names it.
  install -D -m 0644 "$bundle/deploy/$UNIT" "$UNIT_PATH"
  ! systemd_running || systemctl daemon-reload
  install -D -m 0644 "$bundle/deploy/99-eezybot.rules" "$RULES_PATH"
  reload_udev
  systemctl enable --quiet "$UNIT"
  if systemd_running; then
    systemctl restart "$UNIT"
    _say "installed in $PREFIX; $UNIT $(systemctl is-active "$UNIT" || true) (journalctl -u ${UNIT%.service} -f)"
  else
    _say "installed in $PREFIX; systemd is not running here: $UNIT starts at the next boot"
  fi
}

case "${1:-}" in
  -h|--help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//p}' "$0"; exit 0 ;;
esac
[ "$(id -u)" = 0 ] || { _say "run as root: sudo $0 $*"; exit 1; }
case "${1:-}" in
  "") install_bundle ;;
  --uninstall) uninstall ;;
  --keystore)
    [ $# -ge 2 ] || { _say "--keystore needs a directory (a keystore holding enclaves/eezybot/pi, or that enclave)"; exit 2; }
    enclave=/eezybot/pi
    if [ $# -ge 3 ]; then
      { [ "$3" = --enclave ] && [ $# -eq 4 ]; } || { _say "usage: install.sh --keystore DIR [--enclave PATH]"; exit 2; }
      enclave=$4
    fi
    install_keystore "$2" "$enclave" ;;
  *) _say "unknown argument '$1' (--keystore DIR, --uninstall, --help)"; exit 2 ;;
esac
