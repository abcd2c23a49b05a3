#!/usr/bin/env bash
# Runs a command inside a new user+network namespace whose loopback carries multicast, so
# LCM's udpm provider (ttl=0) stays on this machine. Never run LCM multicast outside one.
set -euo pipefail
if [ "${CHAINCOMP_IN_NETNS:-}" != "1" ]; then
  exec unshare -rn env CHAINCOMP_IN_NETNS=1 "$0" "$@"
fi
ip link set lo up
ip link set lo multicast on
ip route add 224.0.0.0/4 dev lo
exec "$@"
