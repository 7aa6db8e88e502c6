#!/usr/bin/env bash
# Installs this bundle (from launch_scripts/cross_build.sh) on a Raspberry Pi as a service
# that starts serial_node at boot. Run as root from the unpacked bundle; safe to repeat
# (an update: unpack the new bundle, run it again).
#
#   sudo deploy/install.sh               install or update, then (re)start the service
#   sudo deploy/install.sh --uninstall   stop and remove it (keeps /etc/default/eezybot)
#
# What it does:
#   /opt/eezybot/                          bin/, launch_scripts/, deploy/, README.txt, docs
#   user and group eezybot (system user, no login), member of dialout
#   /etc/udev/rules.d/99-eezybot.rules     /dev/eezybot for the Arduino; reloads udev
#   /etc/default/eezybot                   from deploy/eezybot.env.example, only if absent
#   /etc/systemd/system/eezybot-serial.service, enabled and (re)started
set -euo pipefail

PREFIX=/opt/eezybot
USER_NAME=eezybot
UNIT=eezybot-serial.service
UNIT_PATH=/etc/systemd/system/$UNIT
RULES_PATH=/etc/udev/rules.d/99-eezybot.rules
ENV_PATH=/etc/default/eezybot

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
  _say "removed (kept $ENV_PATH; delete it by hand if you want)"
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

  # An unprivileged system user that may open the serial port.
  if ! id -u "$USER_NAME" >/dev/null 2>&1; then
    useradd --system --user-group --no-create-home --home-dir /nonexistent \
      --shell /usr/sbin/nologin --comment "EezyBot serial_node" "$USER_NAME"
  fi
  usermod -a -G dialout "$USER_NAME"

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

[ "$(id -u)" = 0 ] || { _say "run as root: sudo $0 $*"; exit 1; }
case "${1:-}" in
  "") install_bundle ;;
  --uninstall) uninstall ;;
  -h|--help) sed -n '2,14s/^# \{0,1\}//p' "$0" ;;
  *) _say "unknown argument '$1' (--uninstall, --help)"; exit 2 ;;
esac
