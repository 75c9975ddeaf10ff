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
# TLS, each optional, each a PEM file (haproxy-config.sh's option of the same name says more):
#   NUPMPC_BALANCER_TLS_CRT       --tls-crt: the certificate clients see (key beside it as .key)
#   NUPMPC_BALANCER_CLIENT_CA     --client-ca: the CA of the callers' client certificates
#   NUPMPC_BALANCER_REPLICA_CA    --replica-ca: the CA the replicas' certificates must chain to
#   NUPMPC_BALANCER_REPLICA_NAME  --replica-name: the name those certificates must carry
#   NUPMPC_BALANCER_CLIENT_CRT    --balancer-crt: the balancer's client certificate to the replicas
# Reload after renewing the files: `kill -USR2 1` in the container (a new worker with the new
# files; the old one finishes its open streams).
# The configuration goes to $TMPDIR (default /tmp: the image's user may write nowhere else).
set -euo pipefail
[ -n "${NUPMPC_REPLICAS:-}" ] || { echo "haproxy-entrypoint: NUPMPC_REPLICAS is empty" >&2; exit 2; }
args=(--listen "${NUPMPC_BALANCER_LISTEN:-0.0.0.0:50051}")
[ -z "${NUPMPC_BALANCER_STATS:-}" ] || args+=(--stats "$NUPMPC_BALANCER_STATS")
[ -z "${NUPMPC_BALANCER_MAXCONN:-}" ] || args+=(--maxconn "$NUPMPC_BALANCER_MAXCONN")
for pair in TLS_CRT:--tls-crt CLIENT_CA:--client-ca REPLICA_CA:--replica-ca REPLICA_NAME:--replica-name \
            CLIENT_CRT:--balancer-crt; do
  variable=NUPMPC_BALANCER_${pair%%:*}
  [ -z "${!variable:-}" ] || args+=("${pair#*:}" "${!variable}")
done
read -r -a replicas <<<"$NUPMPC_REPLICAS"
config=${TMPDIR:-/tmp}/haproxy.cfg
"$(dirname "$0")/haproxy-config.sh" "${args[@]}" "${replicas[@]}" >"$config"
tls="plaintext to clients and replicas"
[ -z "${NUPMPC_BALANCER_TLS_CRT:-}" ] || tls="TLS to clients${NUPMPC_BALANCER_CLIENT_CA:+ (client certificates verified)}"
[ -z "${NUPMPC_BALANCER_REPLICA_CA:-}" ] || tls+=", TLS to the replicas (verified as ${NUPMPC_BALANCER_REPLICA_NAME:-?})"
echo "haproxy-entrypoint: ${#replicas[@]} replicas (${replicas[*]}) behind ${args[1]}: $tls"
exec haproxy -W -db -f "$config"
