#!/usr/bin/env bash
# An SROS2 keystore for the EezyBot graph, without a ROS install: the layout and file
# names of `ros2 security create_keystore` / `create_enclave`, made with the openssl
# command and `eezybot_sros2` (the policy documents, generated from the topic contract).
#
#   launch_scripts/keystore.sh DIR                       CA, governance, /eezybot/pc, /eezybot/pi,
#                                                        /eezybot/bridge_pc, /eezybot/bridge_pi
#   launch_scripts/keystore.sh DIR --enclave /eezybot/pc2   one more enclave (e.g. a second PC)
#
# Options:
#   --enclave PATH    make this enclave (repeatable) instead of the four default ones
#   --role ROLE       the permissions of the --enclave ones: pc = what gui_bridge,
#                     compute_ik, state_publisher, the recorder and the twin use (the
#                     operator PC: a second PC); pi = what serial_node and camera_node use; tools = for stock ROS 2 tools (`ros2
#                     topic echo`, `ros2 param set`, RViz2): every topic of the contract
#                     both ways, /rosout, every service; bridge_pc, bridge_pi = the WAN
#                     bridge of that site (eezybot_wan_bridge pc|pi, when pc.sh or pi.sh
#                     run with ZENOH_ROUTER): exactly the topics that cross the WAN there
#                     (wan/src/crossing.rs), each way, and ros_discovery_info. Default: pi
#                     for /eezybot/pi, bridge_pc and bridge_pi for /eezybot/bridge_pc and
#                     /eezybot/bridge_pi, pc for any other enclave.
#   --namespace NS    the nodes run with -r __ns:=NS (their topics are rt/NS/...)
#   --domain N        only ROS domain N in the governance and permissions (default: every
#                     domain, 0 ... 230: sros2's range; Cyclone DDS refuses documents
#                     with a higher domain id)
#   --renew           rewrite and re-sign the permissions of the enclaves concerned (and the
#                     governance), from the current topic contract and options; their
#                     keys and certificates are kept
#   -h, --help        this text
#
# Running it again keeps what exists: the CA, the governance and every enclave's key,
# certificate and permissions (use --renew for new permissions). Keys are mode 0600 in
# directories only the owner can enter (private/, each enclave).
#
# Layout (as sros2 makes it; the *_ca files are symbolic links, as sros2's):
#   public/ca.cert.pem, identity_ca.cert.pem -> ca.cert.pem, permissions_ca.cert.pem -> ca.cert.pem
#   private/ca.key.pem, identity_ca.key.pem -> ca.key.pem, permissions_ca.key.pem -> ca.key.pem
#   enclaves/governance.xml, governance.p7s
#   enclaves/eezybot/pi/cert.pem key.pem permissions.xml permissions.p7s
#                      identity_ca.cert.pem permissions_ca.cert.pem governance.p7s (links)
# Certificates: EC prime256v1 keys, SHA-256, CA subject CN=sros2CA, enclave subject
# CN=<enclave path>, valid from a day ago (a clock a little behind still accepts them)
# for ten years. Documents S/MIME-signed by the CA (openssl smime -sign -text).
#
# Exit status: 0 done, 1 a step failed, 2 usage error.
set -euo pipefail
EEZYBOT_SCRIPT=keystore.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
eezybot_tool "usage: keystore.sh DIR [--enclave PATH]... [--role pc|pi|tools|bridge_pc|bridge_pi] [--namespace NS] [--domain N] [--renew] (--help)"

DIR=""
ENCLAVES=()
ROLE=""
NAMESPACE=/
DOMAIN=""
RENEW=0
need_value() { [ $# -ge 2 ] && [ -n "$2" ] || eezybot_bad_usage "$1 needs a value"; }
while [ $# -gt 0 ]; do
  case "$1" in
    -h|--help) eezybot_usage; exit 0 ;;
    --enclave|-e) need_value "$@"; ENCLAVES+=("$2"); shift 2 ;;
    --enclave=*) ENCLAVES+=("${1#*=}"); shift ;;
    --role) need_value "$@"; ROLE=$2; shift 2 ;;
    --role=*) ROLE=${1#*=}; shift ;;
    --namespace) need_value "$@"; NAMESPACE=$2; shift 2 ;;
    --namespace=*) NAMESPACE=${1#*=}; shift ;;
    --domain) need_value "$@"; DOMAIN=$2; shift 2 ;;
    --domain=*) DOMAIN=${1#*=}; shift ;;
    --renew) RENEW=1; shift ;;
    -*) eezybot_bad_usage "unknown option $1" ;;
    *) [ -z "$DIR" ] || eezybot_bad_usage "one keystore directory only (got $DIR and $1)"
       DIR=$1; shift ;;
  esac
done

[ -n "$DIR" ] || eezybot_bad_usage "the keystore directory is missing"
[ ! -e "$DIR" ] || [ -d "$DIR" ] || eezybot_bad_usage "$DIR exists and is not a directory"
ROS_NAME='^(/[A-Za-z_][A-Za-z0-9_]*)+$'
for e in "${ENCLAVES[@]}"; do
  [[ $e =~ $ROS_NAME ]] || eezybot_bad_usage "enclave '$e' is not an absolute ROS name such as /eezybot/pc2 (letters, digits, _)"
done
case "$ROLE" in
  ""|pc|pi|tools|bridge_pc|bridge_pi) ;;
  *) eezybot_bad_usage "--role $ROLE: pc, pi, tools, bridge_pc or bridge_pi" ;;
esac
[ -z "$ROLE" ] || [ ${#ENCLAVES[@]} -gt 0 ] || eezybot_bad_usage "--role applies to --enclave PATH"
[ "$NAMESPACE" = / ] || [[ $NAMESPACE =~ $ROS_NAME ]] || eezybot_bad_usage "namespace '$NAMESPACE' is not an absolute ROS namespace such as /arm2"
if [ -n "$DOMAIN" ]; then
  [[ $DOMAIN =~ ^[0-9]+$ ]] && [ "$DOMAIN" -le 230 ] || eezybot_bad_usage "--domain $DOMAIN: a ROS domain id 0 ... 230 (the keystore's documents: Cyclone DDS refuses higher ones)"
fi
[ ${#ENCLAVES[@]} -gt 0 ] || ENCLAVES=(/eezybot/pc /eezybot/pi /eezybot/bridge_pc /eezybot/bridge_pi)
command -v openssl >/dev/null 2>&1 || { eezybot_say "the openssl command is needed (Debian: apt install openssl)"; exit 1; }

# in a source tree: build only the generator, not every node
EEZYBOT_CARGO_SELECT="-p ros_plumbing --bin eezybot_sros2" eezybot_find_binaries eezybot_sros2
SROS2="$EEZYBOT_BIN/eezybot_sros2"
POLICY_ARGS=()
[ -z "$DOMAIN" ] || POLICY_ARGS+=(--domain "$DOMAIN")

mkdir -p "$DIR"
DIR=$(cd "$DIR" && pwd)
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$DIR/public" "$DIR/private" "$DIR/enclaves"
chmod 700 "$DIR/private"

. "$(dirname "${BASH_SOURCE[0]}")/certs.sh"
# sign XML P7S: S/MIME-sign with the permissions CA, as sros2 (text/plain, detached).
sign() {
  openssl smime -sign -text -md sha256 -in "$1" -out "$2.tmp" \
    -signer "$DIR/public/permissions_ca.cert.pem" -inkey "$DIR/private/permissions_ca.key.pem" 2>"$WORK/err" \
    || { cat "$WORK/err" >&2; return 1; }
  chmod 0644 "$2.tmp"
  mv "$2.tmp" "$2"
}

# link TARGET LINK: a relative symbolic link, as sros2's create_symlink.
link() { ln -sfn "$1" "$2"; }

# --- the CA
CA_FILES=("$DIR/public/ca.cert.pem" "$DIR/private/ca.key.pem")
if [ -f "$DIR/public/ca.cert.pem" ] && [ -f "$DIR/private/ca.key.pem" ]; then
  eezybot_say "CA: kept $DIR/public/ca.cert.pem"
elif [ -e "$DIR/public/ca.cert.pem" ] || [ -e "$DIR/private/ca.key.pem" ] \
  || [ -n "$(find "$DIR/enclaves" -name cert.pem -print -quit 2>/dev/null)" ]; then
  eezybot_say "$DIR has enclaves or half a CA (${CA_FILES[*]}): refusing to make a new CA over it"
  eezybot_say "(a new CA would orphan every enclave: use a new directory, or restore the CA files)"
  exit 1
else
  certs_new_key "$DIR/private/ca.key.pem"
  certs_issue sros2CA "$DIR/private/ca.key.pem" "$DIR/public/ca.cert.pem" 3650 \
    "basicConstraints = critical, CA:TRUE, pathlen:1"
  eezybot_say "CA: created $DIR/public/ca.cert.pem (CN=sros2CA, EC prime256v1, until $(openssl x509 -noout -enddate -in "$DIR/public/ca.cert.pem" | cut -d= -f2))"
fi
for which in identity permissions; do
  [ -e "$DIR/public/${which}_ca.cert.pem" ] || link ca.cert.pem "$DIR/public/${which}_ca.cert.pem"
  [ -e "$DIR/private/${which}_ca.key.pem" ] || link ca.key.pem "$DIR/private/${which}_ca.key.pem"
done

# --- the governance
if [ -f "$DIR/enclaves/governance.p7s" ] && [ -f "$DIR/enclaves/governance.xml" ] && [ "$RENEW" = 0 ]; then
  eezybot_say "governance: kept $DIR/enclaves/governance.p7s"
else
  "$SROS2" governance "${POLICY_ARGS[@]}" >"$WORK/governance.xml"
  install -m 0644 "$WORK/governance.xml" "$DIR/enclaves/governance.xml"
  sign "$DIR/enclaves/governance.xml" "$DIR/enclaves/governance.p7s"
  eezybot_say "governance: signed $DIR/enclaves/governance.p7s (authentication required; discovery, liveliness and data encrypted)"
fi

# --- the enclaves
for enclave in "${ENCLAVES[@]}"; do
  d="$DIR/enclaves/${enclave#/}"
  mkdir -p "$d"
  chmod 700 "$d"
  rel=$(realpath --relative-to="$d" "$DIR")
  link "$rel/public/identity_ca.cert.pem" "$d/identity_ca.cert.pem"
  link "$rel/public/permissions_ca.cert.pem" "$d/permissions_ca.cert.pem"
  link "$(realpath --relative-to="$d" "$DIR/enclaves")/governance.p7s" "$d/governance.p7s"
  what=kept
  if [ ! -f "$d/cert.pem" ] || [ ! -f "$d/key.pem" ]; then
    certs_new_key "$d/key.pem"
    certs_issue "$enclave" "$d/key.pem" "$d/cert.pem" 3650 "basicConstraints = CA:FALSE" \
      "$DIR/public/identity_ca.cert.pem" "$DIR/private/identity_ca.key.pem"
    what=created
  fi
  chmod 600 "$d/key.pem"
  role=$ROLE
  if [ -z "$role" ]; then
    case "$enclave" in
      /eezybot/pi) role=pi ;;
      /eezybot/bridge_pc) role=bridge_pc ;;
      /eezybot/bridge_pi) role=bridge_pi ;;
      *) role=pc ;;
    esac
  fi
  if [ ! -f "$d/permissions.p7s" ] || [ ! -f "$d/permissions.xml" ] || [ "$RENEW" = 1 ] || [ "$what" = created ]; then
    "$SROS2" permissions --enclave "$enclave" --role "$role" --namespace "$NAMESPACE" "${POLICY_ARGS[@]}" \
      --cert "$d/cert.pem" >"$WORK/permissions.xml"
    install -m 0644 "$WORK/permissions.xml" "$d/permissions.xml"
    sign "$d/permissions.xml" "$d/permissions.p7s"
    [ "$what" = created ] || what="kept, permissions renewed"
    case "$role" in
      pc) nodes="gui_bridge, compute_ik, state_publisher, recorder, twin" ;;
      pi) nodes="serial_node, camera_node" ;;
      tools) nodes="ROS 2 tools" ;;
      bridge_pc | bridge_pi) nodes="eezybot_wan_bridge ${role#bridge_} (what crosses the WAN)" ;;
    esac
    eezybot_say "enclave $enclave: $what ($d; permissions of $nodes in namespace $NAMESPACE)"
  else
    eezybot_say "enclave $enclave: kept ($d; --renew rewrites its permissions)"
  fi
done
eezybot_say "keystore ready: export ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce ROS_SECURITY_KEYSTORE=$DIR"
