#!/usr/bin/env bash
# Three network namespaces for checking the WAN mode by hand (root): ${P}pc, ${P}wan,
# ${P}pi (P=${ZT_PREFIX:-zt-}). The router's address 10.77.0.1 is in wan; pc
# (10.77.1.2) and pi (10.77.2.2) each have a veth to wan with a route to 10.77.0.1 only.
# wan does not forward (net.ipv4.ip_forward=0): nothing passes between pc and pi except
# through a process in wan (the router). Each of pc and pi is its own DDS "LAN": a
# multicast route on its veth (DDS multicast from it reaches no other site).
#
#   wan/check/netns.sh up      make them (again)
#   wan/check/netns.sh down    delete them
set -euo pipefail
P=${ZT_PREFIX:-zt-}
down() { for n in pc wan pi; do ip netns del "$P$n" 2>/dev/null || true; done; }
case ${1:-} in
  down) down ;;
  up)
    down
    for n in pc wan pi; do ip netns add "$P$n"; ip -n "$P$n" link set lo up; done
    ip netns exec "${P}wan" sysctl -qw net.ipv4.ip_forward=0
    ip -n "${P}wan" addr add 10.77.0.1/32 dev lo
    for side in pc:1 pi:2; do
      n=${side%:*} k=${side#*:}
      ip link add "${P}w$n" type veth peer name "${P}$n-eth"
      ip link set "${P}w$n" netns "${P}wan"
      ip link set "${P}$n-eth" netns "$P$n"
      ip -n "$P$n" link set "${P}$n-eth" name eth0
      ip -n "${P}wan" addr add "10.77.$k.1/24" dev "${P}w$n"
      ip -n "$P$n" addr add "10.77.$k.2/24" dev eth0
      ip -n "${P}wan" link set "${P}w$n" up
      ip -n "$P$n" link set eth0 up
      ip -n "$P$n" route add 10.77.0.1/32 via "10.77.$k.1"
      ip -n "$P$n" route add 224.0.0.0/4 dev eth0
    done
    ;;
  *) echo "usage: netns.sh up|down" >&2; exit 2 ;;
esac
