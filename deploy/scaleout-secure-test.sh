#!/usr/bin/env bash
# The scale-out proof with TLS on both hops and authenticated callers (deploy/scaleout-test.sh
# --secure runs this): three TLS replicas with a tokens file and mTLS behind HAProxy, which
# terminates the clients' TLS (bearer tokens or client certificates), re-encrypts to the
# replicas with its own client certificate (--trusted_balancer_subject) and health-checks
# them over TLS. Each claim is checked (exit 1 naming it):
#   1. transport: the replicas' /readyz answers; plaintext to the balancer's port and to a
#                 replica fails, and so does TLS to a replica without a client certificate;
#   2. callers:   a caller through the balancer with neither token nor certificate is
#                 UNAUTHENTICATED; a session principal A made through the balancer (by
#                 certificate, forwarded as a subject) is A's directly at its replica too,
#                 and NOT_FOUND for B through the balancer and directly, also when B forges
#                 the subject header (the balancer strips it, a replica ignores it from B);
#                 the same with bearer tokens;
#   3. overhead:  24 streams and 1 stream through the balancer, secure against a plaintext
#                 stack started alongside (solves/s, p50, p99);
#   4. failover and rotation: 24 streams authenticated by A's certificate; kill -9 of a
#                 replica: sessions re-created under A (counted at the replicas directly),
#                 0 failed steps, sampled plans equal to cold solves; then the replicas'
#                 and the balancer's certificates are replaced (the replicas re-read theirs,
#                 the balancer reloads): no stream fails, new connections get the new ones.
#   The replicas share a state directory and snapshot key, as deploy/scaleout-test.sh's (whose
#   drain phase proves the move); a kill -9 writes no snapshot, so sessions come back cold.
#
#   deploy/scaleout-secure-test.sh [--quick]     (--quick: short phases, as the ctest entry)
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0
[ "${1:-}" = "--quick" ] && quick=1
if [ $quick = 1 ]; then phase_s=4; else phase_s=20; fi
streams=24
bin="${NUPMPC_BIN_DIR:-build/bin}"
instance="${NUPMPC_BENCHMARKS:-benchmarks}/masses_N30.json"
stubs="${NUPMPC_PYTHON_STUBS:-build/python}"
for p in nupmpc-server nupmpc nupmpc-loadtest nupmpc-scaleout-probe; do
  [ -x "$bin/$p" ] || deploy/build.sh nupmpc-server nupmpc nupmpc-loadtest nupmpc-scaleout-probe
done
[ -f "$stubs/nupmpc/v1/nupmpc_pb2.py" ] || deploy/build.sh nupmpc_python
command -v haproxy >/dev/null || deploy/install-deps.sh
py=/usr/bin/python3
[ -x "$py" ] || py=python3
work=$(mktemp -d /tmp/nupmpc-scaleout-secure.XXXXXX)
cleanup() {
  local children
  children=$(jobs -p)
  [ -z "$children" ] || kill -9 $children 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
say() { echo "== scaleout --secure: $*"; }
fail() {
  echo "scaleout-test --secure: FAILED: $*" >&2
  for f in "$work"/*.log; do echo "--- $f" >&2; tail -5 "$f" >&2; done
  exit 1
}

# --- Certificates and tokens (deploy/make-pki.sh): one CA for every role, each key beside its
# certificate as FILE.key, as a Kubernetes TLS Secret mounted with items gives it.
pki="$work/pki"
pki() { deploy/make-pki.sh "$pki" "$@"; }
issue() {  # NAME SUBJECT server|client: a new key and certificate, moved into place key first
  if [ "$3" = server ]; then pki server "$1" "$2" DNS:localhost,IP:127.0.0.1; else pki client "$1" "$2"; fi
}
serial_of() { openssl x509 -noout -serial -in "$1"; }
served_serial() {  # HOST:PORT: the serial of the certificate a TLS server presents (as the balancer would connect)
  openssl s_client -connect "$1" -alpn h2 -cert "$pki/balancer-client.pem" -key "$pki/balancer-client.pem.key" \
    </dev/null 2>/dev/null | openssl x509 -noout -serial 2>/dev/null || true
}
pki ca /CN=nupmpc-test-ca
issue replica /CN=localhost server
issue frontend /CN=localhost server
issue balancer-client "/CN=nupmpc-balancer/O=nupmpc-test" client
issue alice "/CN=alice/O=plant" client
issue bob "/CN=bob/O=plant" client
balancer_subject=$(pki subject balancer-client)
pki token alice alice
pki token bob bob

read -r lb_port plain_lb_port p1 p2 p3 q1 q2 q3 m1 m2 m3 < <("$py" tests/util/loopback_port.py 11)
declare -A port=([r1]=$p1 [r2]=$p2 [r3]=$p3 [q1]=$q1 [q2]=$q2 [q3]=$q3) metrics_port=([r1]=$m1 [r2]=$m2 [r3]=$m3) pid
lb="127.0.0.1:$lb_port"
plain_lb="127.0.0.1:$plain_lb_port"
as_alice=(--tls_ca_file "$pki/ca.pem" --tls_cert_file "$pki/alice.pem" --tls_key_file "$pki/alice.pem.key")
call() { PYTHONPATH="client/python:$stubs" "$py" deploy/haproxy/secure-call.py --ca "$pki/ca.pem" "$@"; }
cert_of() { echo --cert "$pki/$1.pem" --key "$pki/$1.pem.key"; }

# The replicas' shared state directory and snapshot key (server/README.md).
mkdir -m 700 "$work/state"
(umask 077 && openssl rand 32 > "$work/snapshot.key")
start_replica() {  # rN: TLS, mTLS, tokens, trusting the balancer's certificate
  local name=$1
  "$bin/nupmpc-server" --address "127.0.0.1:${port[$name]}" --metrics_address "127.0.0.1:${metrics_port[$name]}" \
    --tls_cert_file "$pki/replica.pem" --tls_key_file "$pki/replica.pem.key" --tls_client_ca_file "$pki/ca.pem" \
    --tls_reload_interval_s 1 --auth_tokens_file "$pki/tokens" --trusted_balancer_subject "$balancer_subject" \
    --state_dir "$work/state" --snapshot_key_file "$work/snapshot.key" \
    --log_level warn --grace_period_s 2 >>"$work/$name.log" 2>&1 &
  pid[$name]=$!
  # Ready as Kubernetes would probe it: the metrics port's /readyz.
  for _ in $(seq 100); do
    "$py" -c "import urllib.request,sys; urllib.request.urlopen(sys.argv[1], timeout=1)" \
      "http://127.0.0.1:${metrics_port[$name]}/readyz" 2>/dev/null && return 0
    sleep 0.1
  done
  fail "replica $name: /readyz did not answer 200"
}
start_plain_replica() {  # qN: the plaintext stack the overhead is measured against
  "$bin/nupmpc-server" --address "127.0.0.1:${port[$1]}" --log_level warn >>"$work/$1.log" 2>&1 &
  pid[$1]=$!
  for _ in $(seq 100); do
    "$bin/nupmpc" --server "127.0.0.1:${port[$1]}" info >/dev/null 2>&1 && return 0
    sleep 0.1
  done
  fail "plaintext replica $1 did not start"
}
stats="$work/haproxy.sock"
haproxy_master=""
balancer_config() {
  deploy/haproxy/haproxy-config.sh --listen "$lb" --stats "$stats" --tls-crt "$pki/frontend.pem" \
    --client-ca "$pki/ca.pem" --replica-ca "$pki/ca.pem" --replica-name localhost \
    --balancer-crt "$pki/balancer-client.pem" "127.0.0.1:$p1" "127.0.0.1:$p2" "127.0.0.1:$p3" >"$work/haproxy.cfg"
  haproxy -c -q -f "$work/haproxy.cfg" || fail "haproxy rejected the generated TLS configuration"
}
field() {  # replica column: 2 status, 3 current streams, 4 total, 5 last check
  "$py" deploy/haproxy/haproxy-stat.py "$stats" streams 2>/dev/null | awk -v s="$1" -v f="$2" '$1 == s {print $f}'
}
wait_up() {
  for _ in $(seq 100); do
    local all=1
    for n in "$@"; do [ "$(field "$n" 2)" = UP ] || all=0; done
    [ $all = 1 ] && return 0
    sleep 0.1
  done
  "$py" deploy/haproxy/haproxy-stat.py "$stats" streams >&2
  fail "the balancer did not see $* UP over TLS"
}

say "PKI made; the balancer's certificate subject: $balancer_subject"
for n in r1 r2 r3; do start_replica "$n"; done
balancer_config
haproxy -W -db -f "$work/haproxy.cfg" >>"$work/haproxy.log" 2>&1 &
haproxy_master=$!
wait_up r1 r2 r3
say "3 TLS replicas UP behind HAProxy on $lb: the gRPC health check runs over TLS with the balancer's certificate"

# 1. Transport.
! "$bin/nupmpc" --server "$lb" info >/dev/null 2>&1 || fail "plaintext to the balancer's TLS port was answered"
! "$bin/nupmpc" --server "127.0.0.1:$p1" info >/dev/null 2>&1 || fail "plaintext to a replica was answered"
[ "$(call --target "127.0.0.1:$p1" info)" = UNAVAILABLE ] || fail "TLS to a replica without a client certificate"
say "transport: plaintext to the balancer and to a replica fails, and so does TLS to a replica without a" \
    "client certificate"

# 2. Callers.
got=$(call --target "$lb" info)
[ "$got" = UNAUTHENTICATED ] || fail "a caller with neither token nor certificate through the balancer got $got"
got=$(call --target "$lb" --forge "$(pki subject alice)" info)
[ "$got" = UNAUTHENTICATED ] || fail "a forged subject header alone through the balancer got $got"
read -r code id < <(call --target "$lb" $(cert_of alice) create "$instance")
[ "$code" = OK ] || fail "alice could not create a session through the balancer ($code)"
holder=""
for n in r1 r2 r3; do
  if [ "$(call --target "127.0.0.1:${port[$n]}" $(cert_of alice) get "$id")" = OK ]; then holder=$n; fi
done
[ -n "$holder" ] || fail "alice's session (made through the balancer) is not alice's at any replica directly"
expect() {  # WHAT EXPECTED ARGS...: one call, its code must be EXPECTED
  local what=$1 expected=$2
  shift 2
  local got
  got=$(call "$@")
  [ "$got" = "$expected" ] || fail "$what: $got, expected $expected"
}
alice_subject=$(pki subject alice)
expect "alice through the balancer" OK --target "$lb" $(cert_of alice) get "$id"
expect "bob through the balancer" NOT_FOUND --target "$lb" $(cert_of bob) get "$id"
expect "bob directly" NOT_FOUND --target "127.0.0.1:${port[$holder]}" $(cert_of bob) get "$id"
expect "bob forging alice's subject through the balancer" NOT_FOUND --target "$lb" $(cert_of bob) \
  --forge "$alice_subject" get "$id"
expect "bob forging alice's subject directly" NOT_FOUND --target "127.0.0.1:${port[$holder]}" $(cert_of bob) \
  --forge "$alice_subject" get "$id"
expect "bob's token forging alice's subject" NOT_FOUND --target "$lb" --token-file "$pki/bob.token" \
  --forge "$alice_subject" get "$id"
expect "alice closes it" OK --target "$lb" $(cert_of alice) close "$id"
read -r code id < <(call --target "$lb" --token-file "$pki/alice.token" create "$instance")
[ "$code" = OK ] || fail "alice's token could not create a session through the balancer ($code)"
expect "alice's token through the balancer" OK --target "$lb" --token-file "$pki/alice.token" get "$id"
expect "bob's token through the balancer" NOT_FOUND --target "$lb" --token-file "$pki/bob.token" get "$id"
expect "alice's token closes it" OK --target "$lb" --token-file "$pki/alice.token" close "$id"
say "callers: certificate and token principals hold through the balancer and directly (replica $holder);" \
    "B gets NOT_FOUND either way, forged subject headers are ignored"

# 3. Overhead of the secure path against a plaintext stack on the same machine, in turn.
for n in q1 q2 q3; do start_plain_replica "$n"; done
deploy/haproxy/haproxy-config.sh --listen "$plain_lb" "127.0.0.1:$q1" "127.0.0.1:$q2" "127.0.0.1:$q3" >"$work/plain.cfg"
haproxy -W -db -f "$work/plain.cfg" >>"$work/haproxy-plain.log" 2>&1 &
plain_haproxy=$!
lt=("$bin/nupmpc-loadtest" --instance "$instance" --echo=false --json --baseline_rounds 2 --transport_calls 200
    --warmup_s 0.5 --duration_s "$phase_s")
for _ in $(seq 50); do
  if "$bin/nupmpc" --server "$plain_lb" info >/dev/null 2>&1; then break; fi
  sleep 0.1
done
plain_many=$("${lt[@]}" --server "$plain_lb" --concurrency "$streams") || fail "loadtest, plaintext balancer"
secure_many=$("${lt[@]}" --server "$lb" --tls_ca_file "$pki/ca.pem" --token_file "$pki/alice.token" \
  --concurrency "$streams") || fail "loadtest, secure balancer"
plain_one=$("${lt[@]}" --server "$plain_lb" --concurrency 1) || fail "loadtest, 1 stream, plaintext balancer"
secure_one=$("${lt[@]}" --server "$lb" --tls_ca_file "$pki/ca.pem" --token_file "$pki/alice.token" \
  --concurrency 1) || fail "loadtest, 1 stream, secure balancer"
kill "$plain_haproxy" "${pid[q1]}" "${pid[q2]}" "${pid[q3]}" 2>/dev/null || true
"$py" - "$plain_many" "$secure_many" "$plain_one" "$secure_one" "$streams" <<'PY' || fail "the load tests had errors"
import json, sys
runs = [json.loads(a)["levels"][0] for a in sys.argv[1:5]]
print("== scaleout --secure: overhead through the balancer (TLS both hops + token) against plaintext:")
print(f"   {'path':<24} {'solves/s':>9} {'p50 ms':>8} {'p99 ms':>8}")
for name, l in zip([f"plaintext, {sys.argv[5]} streams", f"secure, {sys.argv[5]} streams",
                    "plaintext, 1 stream", "secure, 1 stream"], runs):
    print(f"   {name:<24} {l['solves_per_s']:>9.0f} {l['p50_ms']:>8.3f} {l['p99_ms']:>8.3f}")
for label, p, s in (("streams", runs[0], runs[1]), ("1 stream", runs[2], runs[3])):
    print(f"   secure/plaintext, {label}: solves/s x{s['solves_per_s'] / p['solves_per_s']:.2f}, "
          f"p50 {1000 * (s['p50_ms'] - p['p50_ms']):+.0f} us, p99 {1000 * (s['p99_ms'] - p['p99_ms']):+.0f} us")
sys.exit(0 if all(l["errors"] == {} for l in runs) else 1)
PY

# 4. Failover, then certificate rotation on both hops, under 24 streams of principal A.
probe=("$bin/nupmpc-scaleout-probe" --server "$lb" --instance "$instance" --probe streams --streams "$streams"
       --verify_every 10 "${as_alice[@]}")
# The probe steps until the rotation is done and the streams ran on the new certificates
# (SIGTERM ends it; its duration only bounds a hung run), however slow the machine.
"${probe[@]}" --duration_s 600 >"$work/failover.json" 2>"$work/probe.log" &
probe_pid=$!
for _ in $(seq 200); do
  if [ "$(field r1 3)" -ge 1 ] 2>/dev/null; then break; fi
  sleep 0.05
done
sleep "$("$py" -c "print($phase_s / 3)")"
held=$(field r1 3)
kill -9 "${pid[r1]}"
say "killed replica r1 (SIGKILL) while it held ${held:-0} streams"
alice_sessions() {  # alice's sessions at r2 and r3, asked directly with her certificate
  local total=0 code count
  for n in r2 r3; do
    read -r code count < <(call --target "127.0.0.1:${port[$n]}" $(cert_of alice) list)
    [ "$code" = OK ] || fail "alice's ListSessions at $n directly: $code"
    total=$((total + count))
  done
  echo "$total"
}
for _ in $(seq 20); do
  if [ "$(alice_sessions)" -eq "$streams" ]; then break; fi
  sleep 0.25
done
got=$(alice_sessions)
[ "$got" -eq "$streams" ] || fail "after the failover the live replicas hold $got sessions of alice, expected $streams"
for n in r2 r3; do
  read -r code count < <(call --target "127.0.0.1:${port[$n]}" $(cert_of bob) list)
  [ "$code $count" = "OK 0" ] || fail "bob sees alice's sessions at $n: $code $count"
done
say "failover: the $streams streams' sessions are alice's at the live replicas (directly), bob sees none"

old_replica=$(serial_of "$pki/replica.pem") old_frontend=$(serial_of "$pki/frontend.pem")
issue replica /CN=localhost server
for n in r2 r3; do
  for _ in $(seq 100); do
    if [ "$(served_serial "127.0.0.1:${port[$n]}")" != "$old_replica" ]; then break; fi
    sleep 0.1
  done
  [ "$(served_serial "127.0.0.1:${port[$n]}")" = "$(serial_of "$pki/replica.pem")" ] ||
    fail "replica $n still serves its old certificate"
done
start_replica r1
issue frontend /CN=localhost server
issue balancer-client "/CN=nupmpc-balancer/O=nupmpc-test" client
balancer_config
kill -USR2 "$haproxy_master"  # master-worker reload: the old worker keeps the open streams
wait_up r1 r2 r3
for _ in $(seq 100); do
  if [ "$(served_serial "$lb")" != "$old_frontend" ]; then break; fi
  sleep 0.1
done
[ "$(served_serial "$lb")" = "$(serial_of "$pki/frontend.pem")" ] ||
  fail "the balancer still serves its old certificate"
expect "a new connection through the reloaded balancer" OK --target "$lb" $(cert_of alice) info
kill -0 "$probe_pid" 2>/dev/null || fail "the streams probe ended before the rotation was done"
say "rotation: replicas and balancer serve their new certificates, the balancer's new client certificate is accepted"
sleep "$("$py" -c "print($phase_s / 3)")"  # the streams step on through the new certificates
kill -TERM "$probe_pid"
wait "$probe_pid" || fail "streams probe (failover and rotation)"
out=$(cat "$work/failover.json")
say "failover and rotation: $out"
"$py" -c "import json,sys; d=json.loads(sys.argv[1])
sys.exit(0 if d['affected_streams'] >= 1 and d['failed_steps'] == 0 and d['mismatched'] == 0 and d['verified'] > 0
         and d['twin_mismatched'] == 0 and d['recreated'] >= 1 else 1)" "$out" ||
  fail "a step failed, no stream was affected or re-created, or a plan differs from the core's or its twin's: $out"
say "all checks passed"
