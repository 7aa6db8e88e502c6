#!/usr/bin/env bash
# The Zenoh router of the WAN mode (wan/README.md): both sites' bridges connect to it,
# e.g. on a small VPS both can reach. Listens on ZENOH_LISTEN (default
# tls/0.0.0.0:7447; open that TCP port), TLS with mutual authentication: only a bridge
# with a certificate from the CA in ZENOH_TLS_DIR joins (ca.pem, router.pem, router.key:
# launch_scripts/wan_certs.sh DIR HOST...). tcp/HOST:PORT listens unencrypted and
# unauthenticated: for tests only.
#
#   ZENOH_TLS_DIR=~/wan-certs launch_scripts/router.sh
#
# The binary: wan/target/release/eezybot_wan_router, built on first use (lib.sh:
# eezybot_find_wan_binaries). Ctrl-C (or SIGTERM) stops it; the script then exits 0.
# Exit status 2: a missing or unusable TLS file, a bad ZENOH_LISTEN, a port in use.
set -euo pipefail
EEZYBOT_SCRIPT=router.sh
. "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
trap - EXIT

eezybot_find_wan_binaries eezybot_wan_router
eezybot_say "host $(eezybot_host), listening on ${ZENOH_LISTEN:-tls/0.0.0.0:7447}, TLS files ${ZENOH_TLS_DIR:-(ZENOH_TLS_DIR not set)} (Ctrl-C to stop)"
# the router handles SIGINT / SIGTERM itself (closes its session, exits 0)
trap - INT TERM
exec "$EEZYBOT_WAN_BIN/eezybot_wan_router"
