#!/usr/bin/env bash
# Entry point of the balancer image (deploy/container/Containerfile.haproxy): renders the
# HAProxy configuration with haproxy-config.sh from the environment, then replaces itself
# with HAProxy in the foreground (-db), so that the container's SIGTERM stops HAProxy and
# its exit status is the container's.
#   NUPMPC_REPLICAS          the server replicas, host:port separated by spaces (required)
#   NUPMPC_BALANCER_LISTEN   the address clients dial (default 0.0.0.0:50051)
#   NUPMPC_BALANCER_STATS    optional stats socket: a path, or ipv4@127.0.0.1:PORT (no
#                            socat or python in the image: a TCP socket can be read with
#                            bash's /dev/tcp through `podman exec`)
#   NUPMPC_BALANCER_MAXCONN  optional client connection bound (haproxy-config.sh: 4000)
# The configuration goes to /tmp: the image's user may write nowhere else.
set -euo pipefail
[ -n "${NUPMPC_REPLICAS:-}" ] || { echo "haproxy-entrypoint: NUPMPC_REPLICAS is empty" >&2; exit 2; }
args=(--listen "${NUPMPC_BALANCER_LISTEN:-0.0.0.0:50051}")
[ -z "${NUPMPC_BALANCER_STATS:-}" ] || args+=(--stats "$NUPMPC_BALANCER_STATS")
[ -z "${NUPMPC_BALANCER_MAXCONN:-}" ] || args+=(--maxconn "$NUPMPC_BALANCER_MAXCONN")
read -r -a replicas <<<"$NUPMPC_REPLICAS"
config=/tmp/haproxy.cfg
"$(dirname "$0")/haproxy-config.sh" "${args[@]}" "${replicas[@]}" >"$config"
echo "haproxy-entrypoint: ${#replicas[@]} replicas (${replicas[*]}) behind ${args[1]}"
exec haproxy -W -db -f "$config"
