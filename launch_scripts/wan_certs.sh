#!/usr/bin/env bash
# Certificates for the WAN mode (wan/README.md): a CA, the Zenoh router's certificate
# valid for each HOST (an IP address or a DNS name the bridges connect to), and client
# certificates for the bridges `pc` and `pi`; mutual TLS: the router admits only clients
# whose certificate this CA signed, the bridges only a router this CA signed for HOST.
#
#   launch_scripts/wan_certs.sh DIR HOST...              CA, router, pc, pi
#   launch_scripts/wan_certs.sh DIR HOST... --client pc2  one more client (e.g. a second PC)
#
# Each client certificate has a role, the subject's common name: `pc` or `pi`, from
# the start of the client's NAME (pc, pc2, pc-lab: role pc; pi, pi2, pi-kitchen: role
# pi). The router lets each role publish only its own side's topics (a `pi` may not
# publish `servo_angles`; wan/README.md, "Roles"); a second PC or Pi is one more
# certificate of that role, and the router needs no change for it.
#
# Running it again keeps what exists (CA, keys, certificates); the router's certificate
# is issued again when the HOST list differs from the one it was made for, and a
# client's when its common name is not its role (made before roles existed).
#
# Layout (ZENOH_TLS_DIR of router.sh, pc.sh and pi.sh):
#   ca.pem                   the CA's certificate (every party needs it)
#   router.pem, router.key   for the router (launch_scripts/router.sh)
#   pc.pem, pc.key           for the operator PC's bridge
#   pi.pem, pi.key           for the Raspberry Pi's bridge
#   private/ca.key           the CA's key: keep it here, copy it nowhere
# Copy to each machine ca.pem and its own pair only. Keys: EC prime256v1, PKCS#8,
# mode 0600; certificates valid from a day ago (a clock a little behind still accepts
# them; a Pi has no real-time clock) for 3650 days (the CA) or 825 days.
#
# Exit status: 0 done, 1 a step failed, 2 usage error.
set -euo pipefail
EEZYBOT_SCRIPT=wan_certs.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
eezybot_tool "usage: wan_certs.sh DIR HOST... [--client NAME]... (--help)"

DIR=""
HOSTS=()
CLIENTS=(pc pi)
while [ $# -gt 0 ]; do
  case $1 in
    -h|--help) eezybot_usage; exit 0 ;;
    --client)
      [ $# -ge 2 ] || eezybot_bad_usage "--client needs a NAME"
      if ! [[ $2 =~ ^(pc|pi)([0-9_-][A-Za-z0-9_-]*)?$ ]]; then
        eezybot_bad_usage "client name '$2': its role pc or pi, then optionally a digit, _ or - and more letters, digits, _ and - (pc2, pi-kitchen)"
      fi
      CLIENTS+=("$2"); shift 2 ;;
    -*) eezybot_bad_usage "unknown option $1" ;;
    *) if [ -z "$DIR" ]; then DIR=$1; else HOSTS+=("$1"); fi; shift ;;
  esac
done
[ -n "$DIR" ] || eezybot_bad_usage "no DIR"
[ ${#HOSTS[@]} -gt 0 ] || eezybot_bad_usage "no HOST: the router's address(es) as the bridges reach it (IP or DNS name)"
SANS=()
for h in "${HOSTS[@]}"; do
  if [[ $h =~ ^[0-9]+\.[0-9]+\.[0-9]+\.[0-9]+$ ]] || [[ $h == *:* ]]; then
    SANS+=("IP:$h")
  elif [[ $h =~ ^[A-Za-z0-9]([A-Za-z0-9.-]*[A-Za-z0-9])?$ ]]; then
    SANS+=("DNS:$h")
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
if [ ! -s "$DIR/ca.pem" ] || [ ! -s "$DIR/private/ca.key" ]; then
  certs_new_key "$DIR/private/ca.key"
  certs_issue "EezyBot WAN CA" "$DIR/private/ca.key" "$DIR/ca.pem" 3650 \
    $'basicConstraints = critical, CA:TRUE, pathlen:0\nkeyUsage = critical, keyCertSign, cRLSign\nsubjectKeyIdentifier = hash'
  made+=(ca.pem)
fi
CA=("$DIR/ca.pem" "$DIR/private/ca.key")
LEAF=$'basicConstraints = critical, CA:FALSE\nkeyUsage = critical, digitalSignature\nsubjectKeyIdentifier = hash\nauthorityKeyIdentifier = keyid'

# the router: again when the host list changed (or a new CA was made)
want=$(printf '%s\n' "${SANS[@]}")
if [ ! -s "$DIR/router.pem" ] || [ ! -s "$DIR/router.key" ] || [ "$(cat "$DIR/router.hosts" 2>/dev/null)" != "$want" ] ||
   ! openssl verify -CAfile "$DIR/ca.pem" "$DIR/router.pem" >/dev/null 2>&1; then
  [ -s "$DIR/router.key" ] || certs_new_key "$DIR/router.key"
  certs_issue "eezybot-wan-router" "$DIR/router.key" "$DIR/router.pem" 825 \
    "$LEAF"$'\nextendedKeyUsage = serverAuth\nsubjectAltName = '"$(IFS=,; echo "${SANS[*]}")" "${CA[@]}"
  printf '%s\n' "$want" >"$DIR/router.hosts"
  made+=(router.pem)
fi

# a client's role: the first two letters of its name (checked above); its certificate's
# subject is CN=ROLE, which the router's access control matches
role_of() { printf '%s' "${1:0:2}"; }
for c in "${CLIENTS[@]}"; do
  role=$(role_of "$c")
  if [ ! -s "$DIR/$c.pem" ] || [ ! -s "$DIR/$c.key" ] ||
     ! openssl verify -CAfile "$DIR/ca.pem" "$DIR/$c.pem" >/dev/null 2>&1 ||
     [ "$(openssl x509 -in "$DIR/$c.pem" -noout -subject -nameopt RFC2253 2>/dev/null)" != "subject=CN=$role" ]; then
    [ -s "$DIR/$c.key" ] || certs_new_key "$DIR/$c.key"
    certs_issue "$role" "$DIR/$c.key" "$DIR/$c.pem" 825 "$LEAF"$'\nextendedKeyUsage = clientAuth' "${CA[@]}"
    made+=("$c.pem")
  fi
done

eezybot_say "${made[*]:+made ${made[*]}; }files in $DIR (ZENOH_TLS_DIR), router valid for ${SANS[*]}"
eezybot_say "router: ca.pem router.pem router.key; $(for c in "${CLIENTS[@]}"; do printf '%s (role %s): ca.pem %s.pem %s.key; ' "$c" "$(role_of "$c")" "$c" "$c"; done)CA key private/ca.key stays here"
