#!/usr/bin/env bash
# A certificate for the web panel over HTTPS (README: The panel on a phone or tablet): a
# small CA of the panel's own, and the panel's certificate from it, valid for each HOST
# (an IP address or a DNS name that browsers open the panel at) and for localhost,
# 127.0.0.1 and ::1. Trust ca.pem once on each phone, tablet or PC that opens the panel;
# give gui_bridge the certificate and its key:
#
#   launch_scripts/panel_certs.sh DIR HOST...
#   GUI_BIND=0.0.0.0:8080 GUI_TLS_DIR=DIR launch_scripts/pc.sh     (or run_graph.sh)
#   gui_bridge --ros-args -p bind:=0.0.0.0:8080 -p tls_cert:=DIR/panel.pem -p tls_key:=DIR/panel.key
#
# Running it again keeps what exists (CA, keys, certificate); the panel's certificate is
# issued again when the HOST list differs from the one it was made for (a new address:
# run it again with every HOST, restart gui_bridge; the phones keep trusting the CA), or
# when it runs out within 30 days (renewal: run it again, restart gui_bridge).
#
# The CA may sign only for loopback, private (10/8, 172.16/12, 192.168/16, link-local,
# fc00::/7) and given addresses, and for localhost, the names under .local, .lan,
# .home.arpa and .internal, and the given DNS names (X.509 name constraints): a device
# that trusts it trusts it for nothing else, even if its key got out. A HOST outside that
# (a public address or name added later) needs a new CA: --new-ca (the old CA is kept as
# ca.pem.old; every device must then trust the new ca.pem).
#
# Layout:
#   ca.pem                  the CA's certificate: install it on every browsing device
#   panel.pem, panel.key    the panel's certificate and key (tls_cert, tls_key)
#   private/ca.key          the CA's key: keep it here, copy it nowhere
# Keys: EC prime256v1, PKCS#8, mode 0600. Certificates valid from a day ago, for 3650
# days (the CA) or 825 days (the panel: the longest Apple's devices accept).
#
# Exit status: 0 done, 1 a step failed, 2 usage error.
set -euo pipefail
EEZYBOT_SCRIPT=panel_certs.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
eezybot_tool "usage: panel_certs.sh DIR HOST... [--new-ca] (--help)"

DIR=""
HOSTS=()
NEW_CA=0
while [ $# -gt 0 ]; do
  case $1 in
    -h|--help) eezybot_usage; exit 0 ;;
    --new-ca) NEW_CA=1; shift ;;
    -*) eezybot_bad_usage "unknown option $1" ;;
    *) if [ -z "$DIR" ]; then DIR=$1; else HOSTS+=("$1"); fi; shift ;;
  esac
done
[ -n "$DIR" ] || eezybot_bad_usage "no DIR"
[ ${#HOSTS[@]} -gt 0 ] || eezybot_bad_usage "no HOST: the panel's address(es) or name(s) as browsers open it (e.g. 192.168.1.5 mypc.local)"
SANS=(DNS:localhost IP:127.0.0.1 IP:::1)
PERMITTED=(DNS:localhost DNS:local DNS:lan DNS:home.arpa DNS:internal
  IP:127.0.0.0/255.0.0.0 IP:10.0.0.0/255.0.0.0 IP:172.16.0.0/255.240.0.0 IP:192.168.0.0/255.255.0.0
  IP:169.254.0.0/255.255.0.0 IP:::1/ffff:ffff:ffff:ffff:ffff:ffff:ffff:ffff IP:fc00::/fe00:: IP:fe80::/ffc0::)
for h in "${HOSTS[@]}"; do
  if [[ $h =~ ^[0-9]+\.[0-9]+\.[0-9]+\.[0-9]+$ ]]; then
    SANS+=("IP:$h"); PERMITTED+=("IP:$h/255.255.255.255")
  elif [[ $h == *:* ]] && [[ $h =~ ^[0-9A-Fa-f:]+$ ]]; then
    SANS+=("IP:$h"); PERMITTED+=("IP:$h/ffff:ffff:ffff:ffff:ffff:ffff:ffff:ffff")
  elif [[ $h =~ ^[A-Za-z0-9]([A-Za-z0-9.-]*[A-Za-z0-9])?$ ]]; then
    SANS+=("DNS:$h"); PERMITTED+=("DNS:$h")
  else
    eezybot_bad_usage "HOST '$h' is neither an IP address nor a DNS name"
  fi
done
command -v openssl >/dev/null 2>&1 || { eezybot_say "the openssl command is needed (Debian: apt install openssl)"; exit 1; }

mkdir -p "$DIR/private"
DIR=$(cd "$DIR" && pwd)
chmod 700 "$DIR/private"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

. "$(dirname "${BASH_SOURCE[0]}")/certs.sh"

made=()
if [ "$NEW_CA" = 1 ] && [ -s "$DIR/ca.pem" ]; then
  mv -f "$DIR/ca.pem" "$DIR/ca.pem.old"
  rm -f "$DIR/private/ca.key"
fi
if [ ! -s "$DIR/ca.pem" ] || [ ! -s "$DIR/private/ca.key" ]; then
  certs_new_key "$DIR/private/ca.key"
  certs_issue "EezyBot panel CA ($(hostname 2>/dev/null || echo host))" "$DIR/private/ca.key" "$DIR/ca.pem" 3650 \
    $'basicConstraints = critical, CA:TRUE, pathlen:0\nkeyUsage = critical, keyCertSign, cRLSign\nsubjectKeyIdentifier = hash\nnameConstraints = '"$(printf 'permitted;%s,' "${PERMITTED[@]}" | sed 's/,$//')"
  made+=(ca.pem)
fi

# the panel's certificate: again when the host list changed, the CA is new, or it runs
# out within 30 days
want=$(printf '%s\n' "${SANS[@]}")
if [ ! -s "$DIR/panel.pem" ] || [ ! -s "$DIR/panel.key" ] || [ "$(cat "$DIR/panel.hosts" 2>/dev/null)" != "$want" ] ||
   ! openssl verify -CAfile "$DIR/ca.pem" "$DIR/panel.pem" >/dev/null 2>&1 ||
   ! openssl x509 -in "$DIR/panel.pem" -noout -checkend $((30 * 86400)) >/dev/null 2>&1; then
  [ -s "$DIR/panel.key" ] || certs_new_key "$DIR/panel.key"
  certs_issue "eezybot-panel" "$DIR/panel.key" "$WORK/panel.pem" 825 \
    $'basicConstraints = critical, CA:FALSE\nkeyUsage = critical, digitalSignature\nextendedKeyUsage = serverAuth\nsubjectKeyIdentifier = hash\nauthorityKeyIdentifier = keyid\nsubjectAltName = '"$(IFS=,; echo "${SANS[*]}")" \
    "$DIR/ca.pem" "$DIR/private/ca.key"
  if ! openssl verify -CAfile "$DIR/ca.pem" "$WORK/panel.pem" >"$WORK/verify" 2>&1; then
    eezybot_say "the CA in $DIR may not sign for ${HOSTS[*]} (its name constraints: the addresses and names it was made for, README: The panel on a phone or tablet): run again with --new-ca, then trust the new ca.pem on every device"
    sed 's/^/  /' "$WORK/verify" >&2
    exit 1
  fi
  install -m 0644 "$WORK/panel.pem" "$DIR/panel.pem"
  printf '%s\n' "$want" >"$DIR/panel.hosts"
  made+=(panel.pem)
fi

eezybot_say "${made[*]:+made ${made[*]}; }files in $DIR: panel valid for ${SANS[*]} until $(openssl x509 -in "$DIR/panel.pem" -noout -enddate | cut -d= -f2)"
eezybot_say "gui_bridge: -p tls_cert:=$DIR/panel.pem -p tls_key:=$DIR/panel.key (pc.sh, run_graph.sh: GUI_TLS_DIR=$DIR); every browsing device: trust $DIR/ca.pem (README); private/ca.key stays here"
