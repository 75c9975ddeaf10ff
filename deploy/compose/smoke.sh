#!/usr/bin/env bash
# Smoke test of the compose stack: up.sh (the secure stack, with a throwaway PKI made here by
# deploy/make-pki.sh: principals alice and bob, each with a client certificate and a bearer
# token), then through the balancer on the host port
#   1. callers (deploy/haproxy/secure-call.py, one call each; not with --plaintext):
#      a. plaintext HTTP/2 to the balancer's TLS port is not answered;
#      b. TLS with neither token nor client certificate is UNAUTHENTICATED, and so is one
#         that only sends a forged x-nupmpc-client-subject;
#      c. TLS with alice's token: info, and a session created, read and closed;
#      d. TLS with alice's client certificate (the balancer forwards its subject): a session
#         created and read; bob's certificate gets NOT_FOUND for it, also when bob forges
#         alice's subject in x-nupmpc-client-subject (the balancer removes it), and so does
#         bob's token with the forged header; at the replicas directly (a one-shot
#         container in the pod, the nupmpc CLI with alice's certificate) the session is
#         alice's at exactly one replica: the forwarded subject is the principal a direct
#         mTLS caller with that certificate gets;
#   2. 12 Control streams for 5 s (nupmpc-scaleout-probe --probe streams, alice's token): no
#      failed step, no plan that differs from the core's, and how HAProxy spread the streams;
#   3. 20 sessions by client-drawn id, each solved 10 times by id (--probe addressed, alice's
#      certificate): every call reaches its session (none failed, none had to be re-created);
#   4. rotation (not with --plaintext): 6 streams for 12 s; meanwhile every certificate of
#      both hops is issued anew and handed over by up.sh --renew-secrets: the replicas and
#      the balancer serve the new ones, no step fails;
# then Prometheus in the pod, through its HTTP API, each within 30 s of the probes' end:
#   5. its job nupmpc's targets are the three replicas' metrics endpoints, all health "up"
#      (/api/v1/targets; plain HTTP on the pod's loopback);
#   6. the rule groups of deploy/prometheus/nupmpc-alerts.yml are loaded with every rule of
#      the file, each evaluated without error, health "ok" (/api/v1/rules);
#   7. up{job="nupmpc"} is 1 and nupmpc_solves_total (the probes' solves) above 0 on each
#      replica (/api/v1/query);
# then down.sh: every container exits 0 on SIGTERM. Exit status 0 only if all passed.
# --plaintext: the same with up.sh --plaintext (the loopback/dev variant), without 1 and 4.
#
# Usage: deploy/compose/smoke.sh [--port P] [--plaintext]        (default port 50051)
# Environment:
#   NUPMPC_BIN_DIR       the host build with nupmpc-scaleout-probe (default build/bin)
#   NUPMPC_PYTHON_STUBS  the generated Python stubs, for secure-call.py (default build/python)
#   NUPMPC_BENCHMARKS    instances (default benchmarks/; masses_N30.json is used)
#   NUPMPC_SERVER_IMAGE, NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE   see up.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
port=50051 plaintext=0
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port=$2; shift 2 ;;
    --plaintext) plaintext=1; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "smoke.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
probe=${NUPMPC_BIN_DIR:-build/bin}/nupmpc-scaleout-probe
instance=${NUPMPC_BENCHMARKS:-benchmarks}/masses_N30.json
[ -x "$probe" ] || { echo "smoke: no $probe (deploy/build.sh nupmpc-scaleout-probe, or set NUPMPC_BIN_DIR)" >&2; exit 1; }
[ -f "$instance" ] || { echo "smoke: no $instance (set NUPMPC_BENCHMARKS)" >&2; exit 1; }
stubs=${NUPMPC_PYTHON_STUBS:-build/python}
[ $plaintext = 1 ] || [ -f "$stubs/nupmpc/v1/nupmpc_pb2.py" ] ||
  { echo "smoke: no $stubs/nupmpc/v1/nupmpc_pb2.py (deploy/build.sh nupmpc_python, or set NUPMPC_PYTHON_STUBS)" >&2; exit 1; }
failures=()
check() {  # JSON CONDITION WHAT: CONDITION on the probe's JSON object d
  python3 -c "import json, sys; d = json.loads(sys.argv[1]); sys.exit(0 if ($2) else 1)" "$1" ||
    { echo "smoke: FAIL: $3"; failures+=("$3"); }
}
# Calls each replica took in a backend: the difference of HAProxy's totals around a probe.
spread() {  # BACKEND BEFORE
  join <(sort <<<"$2") <(stack_servers "$1" | sort) | awk '{ printf "%s%s %d", sep, $1, $9 - $5; sep = ", " }'
}

# shellcheck source=deploy/compose/stack-env.sh
. deploy/compose/stack-env.sh
work=$(mktemp -d /tmp/nupmpc-compose-smoke.XXXXXX)
pki=$work/pki
secure=() as_alice_token=() as_alice_cert=()
if [ $plaintext = 0 ]; then
  stack_make_pki "$pki"
  for who in alice bob; do
    deploy/make-pki.sh "$pki" client "$who" "/CN=$who/O=plant"
    deploy/make-pki.sh "$pki" token "$who" "$who"
  done
  as_alice_token=(--tls_ca_file "$pki/ca.pem" --token_file "$pki/alice.token")
  as_alice_cert=(--tls_ca_file "$pki/ca.pem" --tls_cert_file "$pki/alice.pem" --tls_key_file "$pki/alice.pem.key")
  secure=(--pki "$pki")
else
  secure=(--plaintext)
fi
deploy/compose/up.sh --port "$port" "${secure[@]}"
nupmpc_podman_quiet=1 nupmpc_stack_setup
trap 'deploy/compose/down.sh || true; rm -rf "$work"' EXIT
server=127.0.0.1:$port

if [ $plaintext = 0 ]; then
  call() { PYTHONPATH="client/python:$stubs" /usr/bin/python3 deploy/haproxy/secure-call.py --target "$server" --ca "$pki/ca.pem" "$@"; }
  alice_cert=(--cert "$pki/alice.pem" --key "$pki/alice.pem.key")
  bob_cert=(--cert "$pki/bob.pem" --key "$pki/bob.pem.key")
  expect() {  # WHAT EXPECTED ARGS...: one call through the balancer; its answer must be EXPECTED
    local what=$1 expected=$2 got
    shift 2
    got=$(call "$@")
    if [ "$got" = "$expected" ]; then echo "smoke: callers: $what: $got"
    else echo "smoke: FAIL: callers: $what: $got, expected $expected"; failures+=("callers: $what"); fi
  }
  # a. The balancer's port speaks TLS only.
  got=$(call --plaintext info)
  if [ "$got" != OK ]; then echo "smoke: callers: plaintext to the balancer's TLS port: $got (not answered)"
  else echo "smoke: FAIL: callers: plaintext to the balancer's TLS port was answered"; failures+=("callers: plaintext"); fi
  # b. The balancer's own certificate is nobody's principal.
  alice_subject=$(deploy/make-pki.sh "$pki" subject alice)
  expect "TLS with neither token nor certificate" UNAUTHENTICATED info
  expect "TLS with only a forged subject header ($alice_subject)" UNAUTHENTICATED --forge "$alice_subject" info
  # c. Tokens pass through the balancer unchanged.
  expect "alice's token, info" OK --token-file "$pki/alice.token" info
  read -r code id < <(call --token-file "$pki/alice.token" create "$instance")
  [ "$code" = OK ] || { echo "smoke: FAIL: callers: alice's token could not create a session ($code)"; failures+=("callers: token create"); }
  expect "alice's token reads her session" OK --token-file "$pki/alice.token" get "$id"
  expect "bob's token reads alice's (token) session" NOT_FOUND --token-file "$pki/bob.token" get "$id"
  expect "alice's token closes her session" OK --token-file "$pki/alice.token" close "$id"
  # d. A client certificate is verified by the balancer and its subject forwarded.
  read -r code id < <(call "${alice_cert[@]}" create "$instance")
  [ "$code" = OK ] || { echo "smoke: FAIL: callers: alice's certificate could not create a session ($code)"; failures+=("callers: mTLS create"); }
  expect "alice's certificate reads her session" OK "${alice_cert[@]}" get "$id"
  expect "bob's certificate reads alice's (certificate) session" NOT_FOUND "${bob_cert[@]}" get "$id"
  expect "bob's certificate forging alice's subject" NOT_FOUND "${bob_cert[@]}" --forge "$alice_subject" get "$id"
  expect "bob's token forging alice's subject" NOT_FOUND --token-file "$pki/bob.token" --forge "$alice_subject" get "$id"
  # The replicas are on the pod's loopback only: a one-shot container of the server image in
  # the pod asks each directly (nupmpc sessions: ListSessions, the caller's own sessions), with
  # alice's and then bob's certificate, copied for the image's user.
  direct=$work/direct
  mkdir -p "$direct"
  cp "$pki/ca.pem" "$pki/alice.pem" "$pki/alice.pem.key" "$pki/bob.pem" "$pki/bob.pem.key" "$direct/"
  chown -R 10001:10001 "$direct"
  read -r -d '' direct_sessions <<'SH' || true
for who in alice bob; do
  for replica in 127.0.0.1:50061 127.0.0.1:50062 127.0.0.1:50063; do
    out=$(nupmpc --server "$replica" --tls_ca_file /d/ca.pem --tls_cert_file "/d/$who.pem" \
            --tls_key_file "/d/$who.pem.key" --deadline_ms 5000 sessions 2>&1)
    echo "$who $replica $? $(awk '{ print $1 }' <<<"$out" | paste -sd, | grep . || echo none)"
  done
done
SH
  answers=$("${podman_base[@]}" run --rm --pod "$stack_pod" -v "$direct:/d:ro" \
              --entrypoint bash "${NUPMPC_SERVER_IMAGE:-localhost/nupmpc:latest}" -c "$direct_sessions" \
              2>"$work/direct.err") || answers+=$'\n'"podman run: $(tail -n 2 "$work/direct.err")"
  verdict=$(/usr/bin/python3 - "$id" "$answers" <<'PY'
import sys
session, lines = sys.argv[1], [l.split() for l in sys.argv[2].splitlines() if l.strip()]
rows = [l for l in lines if len(l) == 4 and l[0] in ("alice", "bob")]
holders = [r for who, r, rc, ids in rows if who == "alice" and session in ids.split(",")]
bad = [" ".join(l) for l in lines if l not in rows or l[2] != "0"]
bob = [r for who, r, rc, ids in rows if who == "bob" and ids != "none"]
ok = len(rows) == 6 and not bad and len(holders) == 1 and not bob
print(("smoke: callers: " if ok else "smoke: FAIL: callers: ") +
      f"directly at the replicas alice's certificate finds her session at {', '.join(holders) or 'none'}; "
      f"bob's finds sessions at {', '.join(bob) or 'none'}" + (f"; errors: {'; '.join(bad)}" if bad else ""))
PY
)
  echo "$verdict"
  case "$verdict" in *FAIL*) failures+=("callers: the forwarded subject is not the direct mTLS principal") ;; esac
fi

before=$(stack_servers streams)
streams=$("$probe" --server "$server" "${as_alice_token[@]}" --instance "$instance" --probe streams --streams 12 \
  --duration_s 5)
echo "smoke: streams: $streams"
echo "smoke: streams: Control streams per replica (HAProxy): $(spread streams "$before")"
check "$streams" 'd["failed_steps"] == 0 and d["mismatched"] == 0 and d["no_plan"] == 0 and d["verified"] > 0' \
  "streams: a step failed or a plan differs from the core's"

before=$(stack_servers pinned)
addressed=$("$probe" --server "$server" "${as_alice_cert[@]}" --instance "$instance" --probe addressed --sessions 20 --solves 10)
echo "smoke: addressed: $addressed"
echo "smoke: addressed: calls by id per replica (HAProxy): $(spread pinned "$before")"
check "$addressed" 'd["failed"] == 0 and d["recreated"] == 0 and d["miscounted"] == 0 and d["solves"] == 200' \
  "addressed: a call by session id missed its session"

# Rotation on both hops under load (not with --plaintext): 6 Control streams (alice's token)
# for 12 s; after 3 s the replicas', the balancer's and its client certificate are issued
# anew and `up.sh --renew-secrets` hands them over. The replicas must serve the new one
# (read in the pod's network namespace, as the balancer connects), the balancer too, and no
# step may fail.
if [ $plaintext = 0 ]; then
  infra_pid=$("${podman_base[@]}" inspect --format '{{.State.Pid}}' \
                "$("${podman_base[@]}" pod inspect "$stack_pod" --format '{{.InfraContainerID}}')")
  served_serial() {  # PORT [in-pod]: the serial of the certificate served there
    local connect=(openssl s_client -connect "127.0.0.1:$1" -cert "$pki/balancer-client.pem"
                   -key "$pki/balancer-client.pem.key")
    [ "${2:-}" != in-pod ] || connect=(nsenter -t "$infra_pid" -n "${connect[@]}")
    "${connect[@]}" </dev/null 2>/dev/null | openssl x509 -noout -serial 2>/dev/null || true
  }
  "$probe" --server "$server" "${as_alice_token[@]}" --instance "$instance" --probe streams --streams 6 \
    --duration_s 12 >"$work/rotation.json" 2>"$work/rotation.err" &
  rotation_probe=$!
  sleep 3
  deploy/make-pki.sh "$pki" server replica /CN=localhost DNS:localhost,IP:127.0.0.1
  deploy/make-pki.sh "$pki" server frontend "/CN=$(hostname)" "DNS:localhost,IP:127.0.0.1,DNS:$(hostname)"
  deploy/make-pki.sh "$pki" client balancer-client /O=nupmpc/CN=nupmpc-balancer
  deploy/compose/up.sh --renew-secrets --pki "$pki"
  new_replica=$(openssl x509 -noout -serial -in "$pki/replica.pem")
  new_frontend=$(openssl x509 -noout -serial -in "$pki/frontend.pem")
  rotated="" deadline=$((SECONDS + 15))
  while [ "$SECONDS" -lt "$deadline" ]; do
    rotated=""
    for replica_port in 50061 50062 50063; do
      [ "$(served_serial $replica_port in-pod)" = "$new_replica" ] && rotated+="r${replica_port#5006} "
    done
    [ "$(served_serial "$port")" = "$new_frontend" ] && rotated+="balancer"
    [ "$rotated" = "r1 r2 r3 balancer" ] && break
    sleep 0.5
  done
  if [ "$rotated" = "r1 r2 r3 balancer" ]; then echo "smoke: rotation: the replicas and the balancer serve their new certificates"
  else echo "smoke: FAIL: rotation: only ${rotated:-none} serve the new certificates"; failures+=("rotation: certificates"); fi
  if wait "$rotation_probe"; then
    rotation=$(cat "$work/rotation.json")
    echo "smoke: rotation: $rotation"
    check "$rotation" 'd["failed_steps"] == 0 and d["mismatched"] == 0 and d["verified"] > 0' \
      "rotation: a step failed while the certificates were renewed"
  else
    echo "smoke: FAIL: rotation: the streams probe failed: $(tail -n 3 "$work/rotation.err")"
    failures+=("rotation: streams probe")
  fi
fi

# Prometheus: each look is one GET through `podman exec` (stack_prometheus) and a judgement of
# its JSON here (the expected count: the three replicas); a look that fails is repeated until
# it passes or 30 s after the probes are up.
read -r -d '' prometheus_judge <<'PY' || true
import json, re, sys
what, expected = sys.argv[1], int(sys.argv[2])
try:
    data = json.load(sys.stdin)
except ValueError:
    print("no answer from Prometheus")
    sys.exit(1)
if data.get("status") != "success":
    print(f"API status {data.get('status')}: {data.get('error')}")
    sys.exit(1)
data = data["data"]
if what == "targets":
    targets = sorted((t["labels"].get("instance", t["scrapeUrl"]), t["health"], t.get("lastError", ""))
                     for t in data["activeTargets"] if t["labels"].get("job") == "nupmpc")
    print(", ".join(f"{i} {h}" + (f" ({e})" if e else "") for i, h, e in targets) or "no targets of job nupmpc")
    sys.exit(0 if len(targets) == expected and all(h == "up" for _, h, _ in targets) else 1)
if what == "rules":
    text = open("deploy/prometheus/nupmpc-alerts.yml").read()
    want_groups = set(re.findall(r"^  - name:\s*(\S+)", text, re.M))
    want_rules = set(re.findall(r"^\s*- (?:alert|record):\s*(\S+)", text, re.M))
    groups = {g["name"]: g for g in data["groups"] if g["name"] in want_groups}
    rules = {r["name"]: r for g in groups.values() for r in g["rules"]}
    missing = sorted(want_groups - groups.keys()) + sorted(want_rules - rules.keys())
    unhealthy = [f"{n} {r['health']}" + (f" ({r['lastError']})" if r.get("lastError") else "")
                 for n, r in sorted(rules.items()) if r["health"] != "ok"]
    print("; ".join(f"group {n} ({g['file']}): {len(g['rules'])} rules, "
                    f"{sum(r['type'] == 'alerting' for r in g['rules'])} of them alerts, health "
                    + ",".join(sorted({r['health'] for r in g['rules']})) for n, g in sorted(groups.items()))
          + (f"; missing: {', '.join(missing)}" if missing else "")
          + (f"; not evaluated or failing: {', '.join(unhealthy)}" if unhealthy else ""))
    sys.exit(0 if groups and not missing and not unhealthy else 1)
# An instant query: one sample per replica, each above 0.
samples = sorted((s["metric"].get("instance", "?"), float(s["value"][1])) for s in data["result"])
print(", ".join(f"{i} {v:g}" for i, v in samples) or "no samples")
sys.exit(0 if len(samples) == expected and all(v > 0 for _, v in samples) else 1)
PY
prometheus_start=$(date +%s%N) prometheus_deadline=$((SECONDS + 30))
prometheus_expect() {  # WHAT PATH FAILURE
  local answer
  until answer=$(stack_prometheus "$2" | python3 -c "$prometheus_judge" "$1" 3); do
    if [ "$SECONDS" -ge "$prometheus_deadline" ]; then
      echo "smoke: FAIL: prometheus: $3 within 30 s: ${answer:-no answer}"
      failures+=("prometheus: $3")
      return 0
    fi
    sleep 0.5
  done
  echo "smoke: prometheus: $1 after" \
       "$(awk -v a="$prometheus_start" -v b="$(date +%s%N)" 'BEGIN { printf "%.1f s", (b - a) / 1e9 }'): $answer"
}
query_path() { echo "/api/v1/query?query=$(python3 -c 'import sys, urllib.parse; print(urllib.parse.quote(sys.argv[1]))' "$1")"; }
prometheus_expect targets '/api/v1/targets?state=active' "the 3 replicas' metrics endpoints are not all up"
prometheus_expect rules /api/v1/rules "the rules of deploy/prometheus/nupmpc-alerts.yml are not all loaded and evaluated"
prometheus_expect 'up{job="nupmpc"}' "$(query_path 'up{job="nupmpc"}')" 'up{job="nupmpc"} is not 1 on each replica'
prometheus_expect 'sum by (instance) (nupmpc_solves_total)' "$(query_path 'sum by (instance) (nupmpc_solves_total)')" \
  "the probes' solves (nupmpc_solves_total) are not above 0 on each replica"

trap 'rm -rf "$work"' EXIT
deploy/compose/down.sh || failures+=("down: a container did not exit 0 on SIGTERM")
python3 - "$streams" <<'PY'
import json, sys
d = json.loads(sys.argv[1])
print(f"smoke: {d['streams']} streams through the balancer: {d['solves_per_s']:.0f} solves/s,"
      f" p50 {d['p50_ms']:.2f} ms, p99 {d['p99_ms']:.2f} ms")
PY
if [ ${#failures[@]} -gt 0 ]; then echo "smoke: FAILED: ${failures[*]}"; exit 1; fi
if [ $plaintext = 1 ]; then echo "smoke: compose stack (plaintext loopback/dev variant) passed"
else echo "smoke: compose stack (secure: TLS both hops, tokens and client certificates) passed"; fi
