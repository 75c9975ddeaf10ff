#!/usr/bin/env bash
# Prints an HAProxy 2.6 configuration that puts nupmpc-server replicas behind one address.
#
#   deploy/haproxy/haproxy-config.sh --listen HOST:PORT [--stats SOCKET] [--maxconn N] [TLS OPTIONS]
#       REPLICA_HOST:PORT...
#
# --maxconn (default 4000) bounds the client connections: each holds two file
# descriptors, and haproxy refuses to start when the process's limit (ulimit -n) is lower.
#
# TLS (all files PEM; a certificate's key beside it as FILE.key, or in FILE itself):
#   --tls-crt FILE       clients speak TLS to the balancer, which presents this certificate
#   --client-ca FILE     clients may present a certificate this CA signed (mTLS); the balancer
#                        verifies it and names the caller to the replicas in the header
#                        x-nupmpc-client-subject (its subject, RFC 2253). A client's own such
#                        header is always removed. Bearer tokens pass through unchanged.
#   --replica-ca FILE    the balancer speaks TLS to the replicas and requires their
#                        certificates to be signed by this CA and to name --replica-name
#   --replica-name NAME  the name the replicas' certificates carry (DNS or IP SAN)
#   --balancer-crt FILE  the client certificate the balancer presents to the replicas: the
#                        one their --trusted_balancer_subject names
# Certificates are read at start and at each reload (master-worker: SIGUSR2 to the master,
# or `reload` on its master CLI): a reload starts a new worker with the new files while the
# old one finishes its open streams.
#
# The routing contract (proto/nupmpc/v1/nupmpc.proto, above MpcService):
#  * calls with the x-nupmpc-session header (everything addressed by a session id, and the
#    CreateSession that chose the id) go to backend "pinned": the header hashed
#    consistently onto the live replicas, so a session's calls all reach its replica, and
#    losing or adding a replica moves only the sessions hashed to it;
#  * everything else (Control streams that create their own session, SolveOnce, info)
#    goes to backend "streams": least connections first. An HTTP/2 stream stays on the
#    replica that accepted it.
# Health: HAProxy 2.6 has no gRPC health check, so the check speaks the few HTTP/2 frames
# of a grpc.health.v1.Health/Check call itself (tcp-check, bytes below) and expects the
# answer SERVING. A replica stopping with --drain_delay_s reports NOT_SERVING first and is
# taken out before it stops accepting; a replica that died fails the connect.
set -euo pipefail

listen="" stats="" maxconn=4000 tls_crt="" client_ca="" replica_ca="" replica_name="" balancer_crt=""
replicas=()
while [ $# -gt 0 ]; do
  case "$1" in
    --listen) listen="$2"; shift 2 ;;
    --stats) stats="$2"; shift 2 ;;
    --maxconn) maxconn="$2"; shift 2 ;;
    --tls-crt) tls_crt="$2"; shift 2 ;;
    --client-ca) client_ca="$2"; shift 2 ;;
    --replica-ca) replica_ca="$2"; shift 2 ;;
    --replica-name) replica_name="$2"; shift 2 ;;
    --balancer-crt) balancer_crt="$2"; shift 2 ;;
    -h|--help) sed -n '2,40p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "haproxy-config.sh: unknown option $1" >&2; exit 2 ;;
    *) replicas+=("$1"); shift ;;
  esac
done
if [ -z "$listen" ] || [ ${#replicas[@]} -eq 0 ]; then
  echo "usage: haproxy-config.sh --listen HOST:PORT [--stats SOCKET] REPLICA_HOST:PORT..." >&2
  exit 2
fi
usage_error() { echo "haproxy-config.sh: $*" >&2; exit 2; }
[ -z "$client_ca" ] || [ -n "$tls_crt" ] || usage_error "--client-ca: needs --tls-crt (client certificates need TLS)"
[ -z "$replica_ca" ] || [ -n "$replica_name" ] || usage_error "--replica-ca: needs --replica-name (the name to verify)"
[ -z "$replica_name" ] || [ -n "$replica_ca" ] || usage_error "--replica-name: needs --replica-ca"
[ -z "$balancer_crt" ] || [ -n "$replica_ca" ] || usage_error "--balancer-crt: needs --replica-ca (TLS to the replicas)"
bind_tls="" server_tls="" check_connect="tcp-check connect"
if [ -n "$tls_crt" ]; then
  bind_tls=" ssl crt $tls_crt alpn h2"
  [ -z "$client_ca" ] || bind_tls+=" verify optional ca-file $client_ca"
fi
if [ -n "$replica_ca" ]; then
  # Every setting applies to the health check's connection too (HAProxy: "All SSL settings
  # are common to health checks and traffic"), so the check is a TLS call like any other.
  server_tls=" ssl verify required ca-file $replica_ca verifyhost $replica_name alpn h2"
  [ -z "$balancer_crt" ] || server_tls+=" crt $balancer_crt"
  check_connect="tcp-check connect ssl alpn h2"
fi

# A gRPC call as HTTP/2 frames: the client preface, an empty SETTINGS frame, HEADERS
# (stream 1, END_HEADERS; HPACK literals without Huffman coding: :method POST, :scheme
# http, :path /grpc.health.v1.Health/Check, :authority localhost, content-type
# application/grpc, te trailers) and DATA (END_STREAM) with an empty HealthCheckRequest
# (gRPC framing: not compressed, length 0). deploy/scaleout-test.sh shows the check
# taking a replica out when it reports NOT_SERVING.
preface=505249202a20485454502f322e300d0a0d0a534d0d0a0d0a
settings=000000040000000000
headers=00004b0104000000018386041c2f677270632e6865616c74682e76312e4865616c74682f436865636b01096c6f63616c686f73740f10106170706c69636174696f6e2f677270630002746508747261696c657273
data=0000050001000000010000000000
# The answer's DATA payload: gRPC framing (not compressed, length 2) and the
# HealthCheckResponse {status: SERVING} (field 1, varint 1; NOT_SERVING is 2). The check
# first waits for either answer, then decides on what arrived (min-recv 0): a single
# "expect SERVING" would wait out "timeout check" on a NOT_SERVING answer, since the
# HTTP/2 connection stays open, and so take a draining replica out seconds later.
answered='0000000002080[12]'
serving=00000000020801

cat <<CONFIG
# Generated by deploy/haproxy/haproxy-config.sh for ${#replicas[@]} nupmpc replicas.
global
  maxconn ${maxconn}
$( [ -n "$stats" ] && echo "  stats socket $stats mode 600 level admin" )

defaults
  mode http
  timeout connect 1s
  # HAProxy 2.6 pings neither side, so these are what end a stream whose client or replica
  # went silent (a partition, a frozen host): 30 s without a byte on that side. Controllers
  # step every period and never idle that long; a client with a period has re-created its
  # session on another replica after K held periods (about 1 s) long before, and a replica's
  # own keepalive ends a silent client's stream within 15 s only when nothing sits between
  # them. A client that idles longer between steps gets its session re-created: raise both.
  timeout client 30s
  timeout server 30s
  # Only a replica that hangs waits this out: answers, SERVING or not, are decided at once.
  timeout check 2s
  # A request whose replica cannot be connected to is sent to another one.
  option redispatch 1
  retries 2

frontend nupmpc
  bind ${listen}${bind_tls} proto h2
  # Only the balancer names a caller, and only one whose certificate it verified: a client's
  # own header of that name is removed before anything else.
  http-request del-header x-nupmpc-client-subject
$( [ -n "$client_ca" ] && echo '  http-request set-header x-nupmpc-client-subject %[ssl_c_s_dn(,0,rfc2253)] if { ssl_c_used } { ssl_c_verify 0 }' )
  use_backend pinned if { req.hdr(x-nupmpc-session) -m found }
  default_backend streams

backend streams
  balance leastconn
  option tcp-check
  ${check_connect}
  tcp-check send-binary ${preface}${settings}${headers}${data}
  tcp-check expect rbinary ${answered}
  tcp-check expect min-recv 0 binary ${serving}
CONFIG
i=0
for r in "${replicas[@]}"; do
  i=$((i + 1))
  echo "  server r$i $r proto h2 check inter 500ms fall 2 rise 2${server_tls}"
done
cat <<CONFIG

backend pinned
  balance hdr(x-nupmpc-session)
  hash-type consistent
  # A call whose replica cannot be reached fails (UNAVAILABLE) rather than reaching a
  # replica without its session: the client re-creates the session either way, and a
  # CreateSession sent elsewhere would leave an orphan there.
  no option redispatch
CONFIG
i=0
for r in "${replicas[@]}"; do
  i=$((i + 1))
  echo "  server r$i $r proto h2 track streams/r$i${server_tls}"
done
