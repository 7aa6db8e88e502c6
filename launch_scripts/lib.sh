# Shared by run_graph.sh, pc.sh and pi.sh (sourced, not run): finding or building the
# binaries, ROS arguments for every node, starting nodes, and stopping all of them on
# Ctrl-C / SIGTERM (each child gets SIGINT, is waited for, and is killed if it hangs;
# the script then exits 0).
#
# The caller sets EEZYBOT_SCRIPT (its name, for messages) and calls, in order:
#   eezybot_find_binaries BIN...   -> sets EEZYBOT_BIN (a directory)
#   eezybot_ros_args "$@"          -> sets EEZYBOT_ROS_ARGS (array: the user's ROS arguments)
#   eezybot_start NAME ARG...      -> starts $EEZYBOT_BIN/NAME ARG... in the background
#   eezybot_wait                   -> waits; returns when a node exits or on Ctrl-C/SIGTERM

EEZYBOT_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
EEZYBOT_PIDS=()
EEZYBOT_NAMES=()
EEZYBOT_STOPPING=0

eezybot_say() { echo "[${EEZYBOT_SCRIPT:-eezybot}] $*" >&2; }

# For a script that starts no nodes (keystore.sh, wan_certs.sh): plain exits on Ctrl-C
# and SIGTERM instead of the node handling below, and its usage: `eezybot_usage` prints the
# script's header comment up to its "# Exit status" line; `eezybot_bad_usage MESSAGE` says
# MESSAGE and the usage line, and exits 2.
#   eezybot_tool "usage: NAME ARGS..."
eezybot_tool() {
  EEZYBOT_USAGE=$1
  trap 'exit 130' INT
  trap 'exit 143' TERM
  trap - EXIT
}
eezybot_usage() { sed -n '2,/^# Exit status/s/^# \{0,1\}//p' "$0"; }
eezybot_bad_usage() {
  eezybot_say "$*"
  eezybot_say "$EEZYBOT_USAGE"
  exit 2
}

# Where the binaries come from, in this order:
#  1. EEZYBOT_BIN_DIR, if set;
#  2. bin/ next to launch_scripts/ (a bundle from cross_build.sh, copied to a Pi);
#  3. in a source tree with cargo: `cargo build --release` (progress shown), then target/release
#     (EEZYBOT_CARGO_SELECT: what to build, default every binary: `--bins`);
#  4. in a source tree without cargo: target/release, if it holds the binaries.
eezybot_find_binaries() {
  if [ -n "${EEZYBOT_BIN_DIR:-}" ]; then
    EEZYBOT_BIN="$EEZYBOT_BIN_DIR"
  elif [ -x "$EEZYBOT_ROOT/bin/$1" ]; then
    EEZYBOT_BIN="$EEZYBOT_ROOT/bin"
  elif [ -f "$EEZYBOT_ROOT/Cargo.toml" ] && command -v cargo >/dev/null 2>&1; then
    eezybot_say "building: cargo build --release ${EEZYBOT_CARGO_SELECT:---bins} (the first build takes a few minutes)"
    # shellcheck disable=SC2086 # the selection is words: -p crate --bin name
    (cd "$EEZYBOT_ROOT" && cargo build --release ${EEZYBOT_CARGO_SELECT:---bins}) || {
      eezybot_say "the build failed"; exit 1; }
    EEZYBOT_BIN="$EEZYBOT_ROOT/target/release"
  else
    EEZYBOT_BIN="$EEZYBOT_ROOT/target/release"
  fi
  eezybot_need_binaries "$EEZYBOT_BIN" \
    "build them here (cargo build --release), or cross-build on a PC with
launch_scripts/cross_build.sh and copy the bundle (see README: PC + Raspberry Pi)" "$@"
}

# eezybot_need_binaries DIR HINT BIN...: exits 1, naming the missing ones and then the
# HINT (lines), unless DIR holds every BIN.
eezybot_need_binaries() {
  local dir=$1 hint=$2 b missing=() line
  shift 2
  for b in "$@"; do [ -x "$dir/$b" ] || missing+=("$b"); done
  [ ${#missing[@]} -eq 0 ] && return 0
  eezybot_say "missing in $dir: ${missing[*]}"
  while IFS= read -r line; do eezybot_say "$line"; done <<<"$hint"
  exit 1
}

# The WAN mode's binaries (wan/, its own Cargo project: Zenoh and Cyclone DDS, not in the
# main workspace), in this order:
#  1. EEZYBOT_WAN_BIN_DIR, if set;
#  2. bin/ next to launch_scripts/ (a bundle), if it holds the first one;
#  3. in a source tree with cargo: `cargo build --release` in wan/ (the first build takes
#     several minutes: cmake and libclang-dev are needed), then wan/target/release;
#  4. else wan/target/release, if it holds them.
#   eezybot_find_wan_binaries BIN... -> sets EEZYBOT_WAN_BIN (a directory)
eezybot_find_wan_binaries() {
  if [ -n "${EEZYBOT_WAN_BIN_DIR:-}" ]; then
    EEZYBOT_WAN_BIN="$EEZYBOT_WAN_BIN_DIR"
  elif [ -x "$EEZYBOT_ROOT/bin/$1" ]; then
    EEZYBOT_WAN_BIN="$EEZYBOT_ROOT/bin"
  elif [ -f "$EEZYBOT_ROOT/wan/Cargo.toml" ] && command -v cargo >/dev/null 2>&1; then
    [ -x "$EEZYBOT_ROOT/wan/target/release/$1" ] ||
      eezybot_say "building wan/: cargo build --release (the first build takes several minutes; needs cmake and libclang-dev)"
    (cd "$EEZYBOT_ROOT/wan" && cargo build --release --quiet) || {
      eezybot_say "the build of wan/ failed (Debian: apt install cmake libclang-dev)"; exit 1; }
    EEZYBOT_WAN_BIN="$EEZYBOT_ROOT/wan/target/release"
  else
    EEZYBOT_WAN_BIN="$EEZYBOT_ROOT/wan/target/release"
  fi
  eezybot_need_binaries "$EEZYBOT_WAN_BIN" "build them: cd wan && cargo build --release" "$@"
}

# The WAN mode (wan/README.md): with ZENOH_ROUTER set (tls/HOST:PORT, or tcp/HOST:PORT for
# tests), this site's bridge `eezybot_wan_bridge SIDE` runs beside the nodes, in their ROS
# domain and namespace, and joins the router with the certificate NAME.pem of
# ZENOH_TLS_DIR (NAME: ZENOH_CERT, default SIDE). Without ZENOH_ROUTER nothing changes.
# With SROS2 on as well (eezybot_security), the bridge's DDS participant joins the secured
# LAN under the enclave /eezybot/bridge_SIDE of the same keystore (keystore.sh makes it:
# exactly what crosses the WAN there, each way), checked here as the nodes' are.
#   eezybot_wan SIDE      (after eezybot_ros_args and eezybot_security) -> EEZYBOT_WAN=1 when
#                         on. Checks the bridge's configuration first, as the bridge does
#                         (endpoint, TLS files, its enclave: exit 2 with its message, before
#                         any node starts).
#   eezybot_start_wan     starts the bridge (when on), stopped with the nodes
EEZYBOT_WAN=0
eezybot_wan() {
  local side=$1 code=0
  EEZYBOT_WAN=0
  [ -n "${ZENOH_ROUTER:-}" ] || return 0
  eezybot_find_wan_binaries eezybot_wan_bridge
  EEZYBOT_WAN_ARGS=("$side" --namespace "$(eezybot_namespace)")
  [ -z "${ZENOH_CERT:-}" ] || EEZYBOT_WAN_ARGS+=(--cert "$ZENOH_CERT")
  if [ "$EEZYBOT_SECURE" = 1 ]; then
    eezybot_security "/eezybot/bridge_$side" "eezybot_wan_bridge $side"
    EEZYBOT_WAN_ARGS+=(--enclave "/eezybot/bridge_$side")
  fi
  "$EEZYBOT_WAN_BIN/eezybot_wan_bridge" "${EEZYBOT_WAN_ARGS[@]}" --print-config >/dev/null || code=$?
  if [ "$code" != 0 ]; then
    eezybot_say "the WAN bridge's configuration is unusable (above): not starting"
    trap - EXIT
    exit "$code"
  fi
  EEZYBOT_WAN=1
}
eezybot_start_wan() {
  [ "$EEZYBOT_WAN" = 1 ] || return 0
  "$EEZYBOT_WAN_BIN/eezybot_wan_bridge" "${EEZYBOT_WAN_ARGS[@]}" &
  EEZYBOT_PIDS+=($!)
  EEZYBOT_NAMES+=(eezybot_wan_bridge)
}
eezybot_wan_banner() {
  [ "$EEZYBOT_WAN" = 1 ] || return 0
  eezybot_say "WAN mode: bridge $EEZYBOT_WAN_BIN/eezybot_wan_bridge ${EEZYBOT_WAN_ARGS[*]} to the router $ZENOH_ROUTER, TLS files ${ZENOH_TLS_DIR:-(ZENOH_TLS_DIR not set)}"
}

# The nodes' namespace from the ROS arguments (-r __ns:=/NS or --remap __ns:=/NS; the
# last one wins), else /.
eezybot_namespace() {
  local ns=/ prev= a
  for a in "${EEZYBOT_ROS_ARGS[@]}"; do
    case "$prev:$a" in
      -r:__ns:=*|--remap:__ns:=*) ns=${a#__ns:=} ;;
    esac
    prev=$a
  done
  echo "$ns"
}

# The script's own arguments are ROS arguments for every node. A leading --ros-args is
# accepted and dropped (the nodes get one --ros-args block each).
eezybot_ros_args() {
  EEZYBOT_ROS_ARGS=("$@")
  if [ ${#EEZYBOT_ROS_ARGS[@]} -gt 0 ] && [ "${EEZYBOT_ROS_ARGS[0]}" = "--ros-args" ]; then
    EEZYBOT_ROS_ARGS=("${EEZYBOT_ROS_ARGS[@]:1}")
  fi
}

# The arm configuration the nodes load: ARM_CONFIG if set (empty: the shipped one), else
# the calibration wizard's file, ${XDG_CONFIG_HOME:-~/.config}/eezybot/arm.yaml, when it
# exists; else the shipped config/arm.yaml. Sets EEZYBOT_ARM_CONFIG (the path, or empty)
# and EEZYBOT_ARM_ARGS (`-p arm_config:=PATH`, or nothing), and says which.
eezybot_arm_config() {
  local saved="${XDG_CONFIG_HOME:-${HOME:-}/.config}/eezybot/arm.yaml"
  if [ "${ARM_CONFIG+set}" = set ]; then
    EEZYBOT_ARM_CONFIG=$ARM_CONFIG
  elif [ -f "$saved" ]; then
    EEZYBOT_ARM_CONFIG=$saved
  else
    EEZYBOT_ARM_CONFIG=
  fi
  if [ -n "$EEZYBOT_ARM_CONFIG" ]; then
    [ -f "$EEZYBOT_ARM_CONFIG" ] || { eezybot_say "no arm configuration at $EEZYBOT_ARM_CONFIG (ARM_CONFIG)"; exit 2; }
    EEZYBOT_ARM_ARGS=(-p "arm_config:=$EEZYBOT_ARM_CONFIG")
    eezybot_say "arm configuration: $EEZYBOT_ARM_CONFIG"
  else
    EEZYBOT_ARM_ARGS=()
    eezybot_say "arm configuration: the shipped config/arm.yaml (calibrate in the web panel's Calibrate view, or gui_bridge calibrate)"
  fi
}

# The web panel's address and TLS (README: Exposing the web panel safely): GUI_BIND
# (default 127.0.0.1:8080), and the certificate from GUI_TLS_DIR (panel.pem and
# panel.key, launch_scripts/panel_certs.sh) or GUI_TLS_CERT and GUI_TLS_KEY (the user's
# own); GUI_INSECURE_HTTP=1 serves plain HTTP beyond loopback (the token travels in the
# clear). Sets EEZYBOT_GUI_ARGS (gui_bridge's arguments) and EEZYBOT_GUI_URL (for the
# banner). A file named that does not exist: exit 2 before anything starts. Without
# any of them, gui_bridge gets `bind` only, as before.
eezybot_gui() {
  local bind=${GUI_BIND:-127.0.0.1:8080} cert=${GUI_TLS_CERT:-} key=${GUI_TLS_KEY:-} scheme=http
  if [ -n "${GUI_TLS_DIR:-}" ]; then
    cert=${cert:-$GUI_TLS_DIR/panel.pem}
    key=${key:-$GUI_TLS_DIR/panel.key}
  fi
  EEZYBOT_GUI_ARGS=(-p "bind:=$bind")
  if [ -n "$cert" ] || [ -n "$key" ]; then
    local f
    for f in "$cert" "$key"; do
      [ -n "$f" ] && [ -r "$f" ] || { eezybot_say "no readable TLS file '${f}' (GUI_TLS_DIR, GUI_TLS_CERT, GUI_TLS_KEY; launch_scripts/panel_certs.sh DIR HOST... makes them)"; exit 2; }
    done
    EEZYBOT_GUI_ARGS+=(-p "tls_cert:=$cert" -p "tls_key:=$key")
    scheme=https
  fi
  case "${GUI_INSECURE_HTTP:-}" in
    1|true) EEZYBOT_GUI_ARGS+=(-p "insecure_http:=true") ;;
    ''|0|false) ;;
    *) eezybot_say "GUI_INSECURE_HTTP=${GUI_INSECURE_HTTP}: 1 or nothing"; exit 2 ;;
  esac
  EEZYBOT_GUI_URL="$scheme://$bind/"
}

# Start one node: eezybot_start NAME [ROS ARGS...]. The node gets --ros-args, then the
# given node-specific arguments, then the user's (so the user's win).
eezybot_start() {
  local name=$1; shift
  "$EEZYBOT_BIN/$name" --ros-args "$@" "${EEZYBOT_ROS_ARGS[@]}" &
  EEZYBOT_PIDS+=($!)
  EEZYBOT_NAMES+=("$name")
}

eezybot_stop_all() {
  local i p deadline pids names
  # every child, also one started just before a signal: the trap can run between a
  # node's `&` and eezybot_start recording its pid, and that node was neither stopped
  # nor killed, and the final `wait` waited for it forever
  pids=("${EEZYBOT_PIDS[@]}")
  names=("${EEZYBOT_NAMES[@]}")
  for p in $(jobs -p); do
    case " ${pids[*]} " in *" $p "*) ;; *) pids+=("$p"); names+=("a process just started") ;; esac
  done
  [ ${#pids[@]} -gt 0 ] || return 0
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done
  deadline=$((SECONDS + ${EEZYBOT_STOP_TIMEOUT:-5}))
  for i in "${!pids[@]}"; do
    p=${pids[$i]}
    while kill -0 "$p" 2>/dev/null && [ $SECONDS -lt $deadline ]; do sleep 0.1; done
    if kill -0 "$p" 2>/dev/null; then
      eezybot_say "${names[$i]} (pid $p) did not stop within ${EEZYBOT_STOP_TIMEOUT:-5} s: killing it"
      kill -KILL "$p" 2>/dev/null || true
    fi
  done
  wait 2>/dev/null || true
}

# Ctrl-C / SIGTERM: before eezybot_wait (while building or starting nodes) stop what has
# started and exit 0 at once; in eezybot_wait, let it stop the nodes. Installed when this
# file is sourced, so no signal can leave a started node behind.
eezybot_on_signal() {
  EEZYBOT_STOPPING=1
  eezybot_say "$1: stopping ${EEZYBOT_NAMES[*]:-(nothing started yet)}"
  if [ "$EEZYBOT_WAITING" = 0 ]; then
    trap - EXIT
    eezybot_stop_all
    exit 0
  fi
}
EEZYBOT_WAITING=0
trap 'eezybot_on_signal SIGINT' INT
trap 'eezybot_on_signal SIGTERM' TERM
# any other exit (a failed check under set -e) stops the nodes already started, too
trap 'eezybot_stop_all' EXIT

# Wait until a node exits or a signal arrives, then stop every node. Exits 0 after
# Ctrl-C / SIGTERM, else with the exit code of the node that stopped first.
eezybot_wait() {
  local code=0 i
  EEZYBOT_WAITING=1
  [ "$EEZYBOT_STOPPING" = 0 ] || { trap - EXIT; eezybot_stop_all; exit 0; }
  wait -n "${EEZYBOT_PIDS[@]}" || code=$?
  if [ "$EEZYBOT_STOPPING" = 0 ]; then
    for i in "${!EEZYBOT_PIDS[@]}"; do
      kill -0 "${EEZYBOT_PIDS[$i]}" 2>/dev/null || eezybot_say "${EEZYBOT_NAMES[$i]} exited (code $code): stopping the others"
    done
  else
    code=0
  fi
  trap - EXIT
  eezybot_stop_all
  exit "$code"
}

# One line on where this runs: host name and its IPv4 addresses.
eezybot_host() {
  local addrs
  addrs=$(hostname -I 2>/dev/null | tr ' ' '\n' | grep -E '^[0-9.]+$' | tr '\n' ' ' | sed 's/ *$//')
  echo "$(hostname 2>/dev/null || echo this host)${addrs:+ ($addrs)}"
}

eezybot_banner() {
  eezybot_say "host $(eezybot_host), ROS domain ${ROS_DOMAIN_ID:-0}, binaries $EEZYBOT_BIN"
  [ ${#EEZYBOT_ROS_ARGS[@]} -eq 0 ] || eezybot_say "ROS arguments for every node: ${EEZYBOT_ROS_ARGS[*]}"
}

# The serial device for serial_node: SERIAL_PORT if set (mock = the virtual Arduino),
# else /dev/eezybot (udev rule), else /dev/ttyACM0. Prints nothing; sets EEZYBOT_PORT
# and EEZYBOT_PORT_FOUND (1 if the device exists or is the mock).
eezybot_serial_port() {
  EEZYBOT_PORT_FOUND=1
  if [ "${SERIAL_PORT:-}" = twin ]; then
    EEZYBOT_PORT=twin  # the physics twin, started beside serial_node (eezybot_twin)
    return
  fi
  if [ -n "${SERIAL_PORT:-}" ]; then
    EEZYBOT_PORT=$SERIAL_PORT
  elif [ -e /dev/eezybot ]; then
    EEZYBOT_PORT=/dev/eezybot
  elif [ -e /dev/ttyACM0 ]; then
    EEZYBOT_PORT=/dev/ttyACM0
  else
    EEZYBOT_PORT=/dev/eezybot
  fi
  [ "$EEZYBOT_PORT" = mock ] || [ -e "$EEZYBOT_PORT" ] || EEZYBOT_PORT_FOUND=0
}

# The physics twin (docs/twin.md) for SERIAL_PORT=twin: in a source tree, MuJoCo
# (launch_scripts/install_mujoco.sh) and `cargo build --release -p twin --features
# mujoco`; then `twin --mujoco-check` must pass. Exits 1 with what is missing otherwise.
eezybot_twin() {
  if [ -z "${EEZYBOT_BIN_DIR:-}" ] && [ "$EEZYBOT_BIN" = "$EEZYBOT_ROOT/target/release" ] \
    && [ -f "$EEZYBOT_ROOT/Cargo.toml" ] && command -v cargo >/dev/null 2>&1; then
    eezybot_say "the physics twin: MuJoCo and cargo build --release -p twin --features mujoco"
    ( . "$EEZYBOT_ROOT/launch_scripts/install_mujoco.sh" --env >/dev/null \
      && cd "$EEZYBOT_ROOT" && cargo build --release -p twin --features mujoco ) || {
      eezybot_say "the physics twin could not be built (docs/twin.md: Installing MuJoCo)"; exit 1; }
  fi
  eezybot_need_binaries "$EEZYBOT_BIN" "build it: cargo build --release -p twin --features mujoco (docs/twin.md)" twin
  "$EEZYBOT_BIN/twin" --mujoco-check || {
    eezybot_say "SERIAL_PORT=twin needs a twin built with MuJoCo (docs/twin.md); SERIAL_PORT=mock runs the virtual Arduino"
    exit 1; }
}

# SROS2 (DDS Security), as rcl reads it: on only when ROS_SECURITY_ENABLE is exactly
# `true`; ROS_SECURITY_STRATEGY=Enforce refuses to run unsecured, anything else is
# permissive; ROS_SECURITY_KEYSTORE is the keystore (launch_scripts/keystore.sh), an
# enclave's files are in $ROS_SECURITY_KEYSTORE/enclaves/<enclave>;
# ROS_SECURITY_ENCLAVE_OVERRIDE replaces every node's enclave.
#
#   eezybot_security ENCLAVE "NODES" [ENCLAVE "NODES"]...
#     -> EEZYBOT_SECURE=1 when on. Checks each enclave's directory and six files and says
#        that security is on (keystore, enclave and nodes, strategy). A missing or
#        unreadable file: exit 2 under Enforce, a warning otherwise (the nodes then warn
#        and run unsecured). Off: nothing is printed and nothing changes.
#   eezybot_enclave ENCLAVE -> EEZYBOT_ENCLAVE (array): `--enclave ENCLAVE` when on, else empty
EEZYBOT_SECURE=0
EEZYBOT_ENCLAVE_FILES="cert.pem key.pem identity_ca.cert.pem permissions_ca.cert.pem governance.p7s permissions.p7s"
eezybot_security() {
  local enable=${ROS_SECURITY_ENABLE:-} strategy=${ROS_SECURITY_STRATEGY:-} keystore=${ROS_SECURITY_KEYSTORE:-}
  local override=${ROS_SECURITY_ENCLAVE_OVERRIDE:-} enforce=0 enclave nodes dir f problems=()
  EEZYBOT_SECURE=0
  if [ "$enable" != true ]; then
    [ -z "$enable" ] || [ "$enable" = false ] ||
      eezybot_say "WARNING: ROS_SECURITY_ENABLE=$enable is not \`true\`: security is off (as in rcl, only exactly \`true\` turns it on)"
    return 0
  fi
  EEZYBOT_SECURE=1
  [ "$strategy" != Enforce ] || enforce=1
  if [ -z "$keystore" ]; then
    problems+=("ROS_SECURITY_KEYSTORE is not set: the keystore directory (make one with launch_scripts/keystore.sh DIR)")
  elif [ ! -d "$keystore" ]; then
    problems+=("ROS_SECURITY_KEYSTORE=$keystore is not a directory (make the keystore with launch_scripts/keystore.sh $keystore)")
  else
    while [ $# -ge 2 ]; do
      enclave=${override:-$1}; nodes=$2; shift 2
      dir="$keystore/enclaves/${enclave#/}"
      if [ ! -d "$dir" ]; then
        problems+=("no enclave $enclave in the keystore: $dir is not a directory (launch_scripts/keystore.sh $keystore --enclave $enclave)")
        continue
      fi
      for f in $EEZYBOT_ENCLAVE_FILES; do
        [ -r "$dir/$f" ] || problems+=("$dir/$f is missing or unreadable (enclave $enclave)")
      done
      eezybot_say "security on: keystore $keystore, enclave $enclave${override:+ (ROS_SECURITY_ENCLAVE_OVERRIDE)} for $nodes, strategy $([ $enforce = 1 ] && echo Enforce || echo "Permissive (${strategy:-unset})")"
    done
  fi
  [ ${#problems[@]} -gt 0 ] || return 0
  for f in "${problems[@]}"; do eezybot_say "$f"; done
  if [ $enforce = 1 ]; then
    eezybot_say "ROS_SECURITY_STRATEGY=Enforce: not starting unsecured (README: Securing the link)"
    trap - EXIT
    exit 2
  fi
  eezybot_say "WARNING: ROS_SECURITY_STRATEGY=${strategy:-unset} is not Enforce: the nodes start unsecured where their enclave is unusable"
}

eezybot_enclave() {
  EEZYBOT_ENCLAVE=()
  [ "$EEZYBOT_SECURE" = 0 ] || EEZYBOT_ENCLAVE=(--enclave "$1")
}
