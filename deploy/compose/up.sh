#!/usr/bin/env bash
# Starts the compose stack (deploy/compose/nupmpc-stack.yaml: 3 nupmpc-server replicas, the
# HAProxy balancer and Prometheus in one pod) with `podman kube play`, and waits until the
# balancer answers grpc.health.v1 SERVING on the host, HAProxy's health checks have passed on
# all replicas and Prometheus is ready. Prints the start-up times. Replaces a stack already
# running.
#
# Usage: deploy/compose/up.sh [--port P]     (the balancer's host port, default 50051)
# Environment:
#   NUPMPC_SERVER_IMAGE    the replicas' image (default localhost/nupmpc:latest)
#   NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE   see deploy/container/podman-env.sh
# Needs the images (deploy/container/build-image.sh, deploy/compose/build-balancer-image.sh,
# deploy/compose/build-prometheus-image.sh), catatonit (podman's pod infra process) and
# python3-grpcio (the health check).
set -euo pipefail
cd "$(dirname "$0")/../.."
port=50051
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "up.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
say() { echo "up: $*"; }
die() { echo "up: $*" >&2; exit 1; }
server_image=${NUPMPC_SERVER_IMAGE:-localhost/nupmpc:latest}
balancer_image=localhost/nupmpc-haproxy:latest
prometheus_image=localhost/nupmpc-prometheus:latest

# shellcheck source=deploy/compose/stack-env.sh
. deploy/compose/stack-env.sh
nupmpc_stack_setup
"${podman_base[@]}" image exists "$server_image" || die "no $server_image (deploy/container/build-image.sh)"
"${podman_base[@]}" image exists "$balancer_image" || die "no $balancer_image (deploy/compose/build-balancer-image.sh)"
"${podman_base[@]}" image exists "$prometheus_image" || die "no $prometheus_image (deploy/compose/build-prometheus-image.sh)"
# Without it podman 4.3 cannot make the pod's infra ("pause") image: "finding pause binary".
command -v catatonit >/dev/null || die "catatonit is missing (apt-get install catatonit)"
/usr/bin/python3 -c 'import grpc' 2>/dev/null || die "python3-grpcio is missing (apt-get install python3-grpcio)"
nupmpc_stack_runtime "$server_image"

# A stale image passes every check of its own and fails the routing contract: say so.
revision=$("${podman_base[@]}" image inspect --format '{{index .Labels "org.opencontainers.image.revision"}}' "$server_image")
revision=${revision%-dirty}
if [ -n "$revision" ] && git rev-parse -q --verify "$revision^{commit}" >/dev/null &&
   ! git diff --quiet "$revision" HEAD -- server core client proto; then
  say "WARNING: $server_image is built from $revision; server/ core/ client/ proto/ have changed since" \
      "(rebuild: deploy/container/build-image.sh)"
fi
# The Prometheus image carries its own copy of deploy/prometheus/ (Containerfile.prometheus).
if [ "$("${podman_base[@]}" image inspect --format '{{index .Labels "io.nupmpc.prometheus-config"}}' "$prometheus_image")" != \
     "$(stack_prometheus_config_sum)" ]; then
  say "WARNING: $prometheus_image holds another deploy/prometheus/ than this tree" \
      "(rebuild: deploy/compose/build-prometheus-image.sh)"
fi

# The YAML as committed, with this run's port and image.
start=$(date +%s%N)
sed -e "s/hostPort: 50051/hostPort: $port/" -e "s|image: localhost/nupmpc:latest|image: $server_image|" "$stack_yaml" |
  "${podman_base[@]}" kube play --replace - >/dev/null
played=$(date +%s%N)

# SERVING through the host port means at least one replica passed HAProxy's check; a fresh
# channel per attempt keeps gRPC's reconnect back-off out of the time.
/usr/bin/python3 - "127.0.0.1:$port" <<'PY' || die "the balancer did not answer SERVING within 60 s"
import sys, time
import grpc
deadline = time.monotonic() + 60
while time.monotonic() < deadline:
    with grpc.insecure_channel(sys.argv[1]) as channel:
        try:
            if channel.unary_unary("/grpc.health.v1.Health/Check")(b"", timeout=0.5) == b"\x08\x01":
                sys.exit(0)
        except grpc.RpcError:
            pass
    time.sleep(0.02)
sys.exit(1)
PY
serving=$(date +%s%N)
# HAProxy marks servers UP before their first check: wait for a passed check (L7OK) on each.
all_checked() { [ -n "$servers" ] && awk '$2 != "UP" || $3 != "L7OK" { bad = 1 } END { exit bad }' <<<"$servers"; }
servers='' deadline=$((SECONDS + 30))
until all_checked; do
  [ "$SECONDS" -lt "$deadline" ] || die "replicas not all UP after 30 s: $servers"
  sleep 0.1
  servers=$(stack_servers streams)
done
all_up=$(date +%s%N)
# Prometheus answers /-/ready once its storage is open and the configuration and rules loaded.
deadline=$((SECONDS + 30))
until stack_prometheus /-/ready >/dev/null; do
  [ "$SECONDS" -lt "$deadline" ] || die "Prometheus not ready after 30 s ($("${podman_base[@]}" logs --tail 3 "$stack_pod-prometheus" 2>&1))"
  sleep 0.1
done
prometheus_ready=$(date +%s%N)

s_since() { awk -v a="$start" -v b="$1" 'BEGIN { printf "%.1f s", (b - a) / 1e9 }'; }
say "pod $stack_pod ($server_image, $balancer_image, $prometheus_image, runtime $NUPMPC_PODMAN_RUNTIME)," \
    "balancer on 0.0.0.0:$port, Prometheus on the pod's 127.0.0.1:9090"
say "kube play $(s_since "$played"); SERVING through the balancer after $(s_since "$serving");" \
    "all $(wc -l <<<"$servers") replicas UP in HAProxy after $(s_since "$all_up"); Prometheus ready after $(s_since "$prometheus_ready")"
echo "$servers" | awk '{ print "  " $1, $2, "(check " $3 ")" }'
