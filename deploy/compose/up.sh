#!/usr/bin/env bash
# Starts the compose stack (deploy/compose/nupmpc-stack.yaml: 3 nupmpc-server replicas, the
# HAProxy balancer and Prometheus in one pod) with `podman kube play`, and waits until the
# balancer answers grpc.health.v1 SERVING on the host, HAProxy's health checks have passed on
# all replicas and Prometheus is ready. Prints the start-up times. Replaces a stack already
# running.
#
# Usage: deploy/compose/up.sh [--port P] [--pki DIR | --plaintext]
#        deploy/compose/up.sh --renew-secrets [--pki DIR]
#   --port P          the balancer's host port (default 50051)
#   --pki DIR         the certificates and tokens (PEM; deploy/compose/README.md lists the
#                     files): ca.pem, replica.pem, frontend.pem, balancer-client.pem, each
#                     with its key as FILE.key, and tokens (TOKEN PRINCIPAL [admin] per
#                     line). Default $NUPMPC_COMPOSE_PKI or /var/lib/nupmpc-compose/pki, made
#                     with a CA of its own and one token (principal "operator") if it holds
#                     no ca.pem. Copied into /run/nupmpc-compose/secrets for the containers.
#   --plaintext       the loopback/dev variant (plaintext-variant.py): no TLS and no
#                     authentication anywhere, the balancer published on 127.0.0.1 only
#   --renew-secrets   copy the files of --pki again into the running stack: the replicas
#                     re-read theirs (within 10 s; tokens at once), the balancer reloads in
#                     place (open streams stay on the old worker). Nothing is restarted.
# Environment:
#   NUPMPC_SERVER_IMAGE    the replicas' image (default localhost/nupmpc:latest)
#   NUPMPC_COMPOSE_PKI     the default of --pki
#   NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE   see deploy/container/podman-env.sh
# Needs the images (deploy/container/build-image.sh, deploy/compose/build-balancer-image.sh,
# deploy/compose/build-prometheus-image.sh), catatonit (podman's pod infra process),
# python3-grpcio (the health check), python3-yaml (--plaintext) and openssl; run as root (the
# files are handed to the containers' users).
set -euo pipefail
cd "$(dirname "$0")/../.."
port=50051 plaintext=0 renew=0 pki=${NUPMPC_COMPOSE_PKI:-/var/lib/nupmpc-compose/pki}
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port=$2; shift 2 ;;
    --pki) pki=$2; shift 2 ;;
    --plaintext) plaintext=1; shift ;;
    --renew-secrets) renew=1; shift ;;
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
if [ $renew = 1 ]; then
  "${podman_base[@]}" pod exists "$stack_pod" || die "no pod $stack_pod to renew the files of"
  stack_install_secrets "$pki" || die "the files of $pki could not be installed"
  "${podman_base[@]}" exec "$stack_pod-balancer" bash -c 'kill -USR2 1' || die "the balancer did not reload"
  say "the files of $pki installed; the replicas re-read theirs within 10 s, the balancer reloaded"
  exit 0
fi
"${podman_base[@]}" image exists "$server_image" || die "no $server_image (deploy/container/build-image.sh)"
"${podman_base[@]}" image exists "$balancer_image" || die "no $balancer_image (deploy/compose/build-balancer-image.sh)"
"${podman_base[@]}" image exists "$prometheus_image" || die "no $prometheus_image (deploy/compose/build-prometheus-image.sh)"
# Without it podman 4.3 cannot make the pod's infra ("pause") image: "finding pause binary".
command -v catatonit >/dev/null || die "catatonit is missing (apt-get install catatonit)"
/usr/bin/python3 -c 'import grpc' 2>/dev/null || die "python3-grpcio is missing (apt-get install python3-grpcio)"
[ $plaintext = 0 ] || /usr/bin/python3 -c 'import yaml' 2>/dev/null || die "python3-yaml is missing (apt-get install python3-yaml)"
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

# The certificates and tokens, handed to the containers' users (stack-env.sh).
if [ $plaintext = 0 ]; then
  command -v openssl >/dev/null || die "openssl is missing"
  if [ ! -f "$pki/ca.pem" ]; then
    say "no $pki/ca.pem: making a CA of this machine's own, the stack's certificates and one bearer token"
    stack_make_pki "$pki"
    deploy/make-pki.sh "$pki" token operator operator
    say "clients: --tls_ca_file $pki/ca.pem --token_file $pki/operator.token (principal operator)"
  fi
  # The replicas trust the forwarded caller only from the subject the YAML names.
  trusted=$(sed -n '/name: NUPMPC_TRUSTED_BALANCER_SUBJECT/{n;s/.*value: "\(.*\)"/\1/p;q}' "$stack_yaml")
  subject=$(deploy/make-pki.sh "$pki" subject balancer-client 2>/dev/null) ||
    die "no $pki/balancer-client.pem (the balancer's client certificate)"
  [ "$subject" = "$trusted" ] ||
    die "$pki/balancer-client.pem's subject is $subject; the replicas trust $trusted (NUPMPC_TRUSTED_BALANCER_SUBJECT)"
  stack_install_secrets "$pki" || die "the files of $pki could not be installed"
fi

# The YAML as committed (or its plaintext variant), with this run's port and image.
start=$(date +%s%N)
sed -e "s/hostPort: 50051/hostPort: $port/" -e "s|image: localhost/nupmpc:latest|image: $server_image|" "$stack_yaml" |
  if [ $plaintext = 1 ]; then /usr/bin/python3 deploy/compose/plaintext-variant.py; else cat; fi |
  "${podman_base[@]}" kube play --replace - >/dev/null
played=$(date +%s%N)

# SERVING through the host port means at least one replica passed HAProxy's check; a fresh
# channel per attempt keeps gRPC's reconnect back-off out of the time. grpc.health.v1 needs
# no credentials: TLS with the CA only.
ca_file=""
[ $plaintext = 1 ] || ca_file=$pki/ca.pem
GRPC_VERBOSITY=NONE /usr/bin/python3 - "127.0.0.1:$port" "$ca_file" <<'PY' || die "the balancer did not answer SERVING within 60 s"
import sys, time
import grpc
def channel_to(target, ca_file):
    if not ca_file:
        return grpc.insecure_channel(target)
    with open(ca_file, "rb") as f:
        return grpc.secure_channel(target, grpc.ssl_channel_credentials(root_certificates=f.read()))
deadline = time.monotonic() + 60
while time.monotonic() < deadline:
    with channel_to(sys.argv[1], sys.argv[2]) as channel:
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
if [ $plaintext = 1 ]; then
  variant="PLAINTEXT (loopback/dev): balancer on 127.0.0.1:$port, no TLS, no authentication"
else
  variant="secure: balancer on 0.0.0.0:$port with TLS (CA $pki/ca.pem), tokens or client certificates; TLS to the replicas"
fi
say "pod $stack_pod ($server_image, $balancer_image, $prometheus_image, runtime $NUPMPC_PODMAN_RUNTIME)"
say "$variant; Prometheus on the pod's 127.0.0.1:9090"
say "kube play $(s_since "$played"); SERVING through the balancer after $(s_since "$serving");" \
    "all $(wc -l <<<"$servers") replicas UP in HAProxy after $(s_since "$all_up"); Prometheus ready after $(s_since "$prometheus_ready")"
echo "$servers" | awk '{ print "  " $1, $2, "(check " $3 ")" }'
