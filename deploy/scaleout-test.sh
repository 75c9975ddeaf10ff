#!/usr/bin/env bash
# Several nupmpc-server replicas behind a real HAProxy on loopback, driven through the
# client library; every claim of the routing contract is checked (exit 1 naming it):
#   1. spread:    nupmpc-loadtest, 24 Control streams through the balancer: every replica
#                 gets streams, no errors; solves/s and p50/p99 next to one replica
#                 reached directly (1 stream each way: the proxy hop's cost); Debian's
#                 Prometheus scrapes the replicas with deploy/prometheus/'s rules: all up,
#                 solves stored, the deadline-miss ratio recorded for each;
#   2. addressed: 50 sessions made with client-drawn ids, each solved 20 times by id
#                 through the balancer: every call reaches its session;
#   3. failover:  kill -9 of one replica under 24 streams: each affected stream re-creates
#                 its session elsewhere, cold (a crash writes no snapshot), and no step fails
#                 (the one in flight is resent); sampled plans equal the core's own solve of
#                 the same state to 1e-9;
#   4. drain:     SIGTERM to one replica (--drain_delay_s) under 24 streams of four session
#                 kinds: the balancer takes it out, no step fails, and the sessions move: the
#                 replicas share a state directory and snapshot key, the drained one writes
#                 its sessions' snapshots, and each of its streams re-attaches by id on
#                 another replica, which restores the session (none is re-created);
#
#   In phases 3-5 every stream of nupmpc-scaleout-probe keeps a never-moved twin session in
#   the probe's process: each answered plan equals the twin's, bit for bit (inputs) with the
#   same pass count (a re-created session's twin is re-created too).
#   5. scale-up:  a fourth replica and a balancer reload: new streams reach it;
#   6. compose:   (full run, where podman and the images are) deploy/compose/smoke.sh, the
#                 secure stack and its --plaintext loopback/dev variant.
#
#   deploy/scaleout-test.sh [--quick]            (--quick: short phases, as the ctest entry)
#   deploy/scaleout-test.sh --secure [--quick]   TLS on both hops, tokens and mTLS callers through
#                                                the balancer: deploy/scaleout-secure-test.sh
#
# Needs the build (deploy/build.sh) and haproxy (deploy/install-deps.sh installs it).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--secure" ]; then shift; exec deploy/scaleout-secure-test.sh "$@"; fi
quick=0
[ "${1:-}" = "--quick" ] && quick=1
if [ $quick = 1 ]; then phase_s=4; streams=24; else phase_s=20; streams=24; fi
bin="${NUPMPC_BIN_DIR:-build/bin}"
instance="${NUPMPC_BENCHMARKS:-benchmarks}/masses_N30.json"
command -v prometheus >/dev/null || deploy/install-deps.sh
for p in nupmpc-server nupmpc nupmpc-loadtest nupmpc-scaleout-probe; do
  [ -x "$bin/$p" ] || deploy/build.sh nupmpc-server nupmpc nupmpc-loadtest nupmpc-scaleout-probe
done
command -v haproxy >/dev/null || deploy/install-deps.sh

# Debian's interpreter: it starts in milliseconds (a version manager's shim on PATH can take
# a good part of a second on a loaded machine, too slow to poll the balancer with).
py=/usr/bin/python3
[ -x "$py" ] || py=python3
work=$(mktemp -d /tmp/nupmpc-scaleout.XXXXXX)
cleanup() {
  # Every process of this test is a child of this shell (haproxy runs in the foreground as
  # master and worker), so nothing outlives it.
  local children
  children=$(jobs -p)
  [ -z "$children" ] || kill -9 $children 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
say() { echo "== scaleout: $*"; }
fail() { echo "scaleout-test: FAILED: $*" >&2; for f in "$work"/*.log; do echo "--- $f" >&2; tail -5 "$f" >&2; done; exit 1; }
# Five distinct free ports, drawn while all are held (HAProxy binds with SO_REUSEPORT:
# two processes given one port would silently share it), from outside the range the kernel
# takes outgoing connections' ports from (the replicas restart on theirs).
read -r lb_port p1 p2 p3 p4 m1 m2 m3 m4 prom_port < <("$py" tests/util/loopback_port.py 10)
declare -A port=([r1]=$p1 [r2]=$p2 [r3]=$p3 [r4]=$p4) metrics_port=([r1]=$m1 [r2]=$m2 [r3]=$m3 [r4]=$m4) pid
# Longer than the balancer's worst case to take a replica out (inter 500ms, fall 2, timeout
# check 2s: 3 s when a check hangs), so that a drained replica is seen DOWN before it exits
# even on a loaded machine; it answers NOT_SERVING at once, so it is out after about 1 s.
drain_delay_s=5
# The replicas' shared state directory and snapshot key: a drained replica's sessions are
# restored by whichever replica its clients' reconnects reach (server/README.md).
mkdir -m 700 "$work/state"
(umask 077 && openssl rand 32 > "$work/snapshot.key")
start_replica() {  # name
  local name=$1
  "$bin/nupmpc-server" --address "127.0.0.1:${port[$name]}" --metrics_address "127.0.0.1:${metrics_port[$name]}" \
    --log_level warn --drain_delay_s "$drain_delay_s" --grace_period_s 2 \
    --state_dir "$work/state" --snapshot_key_file "$work/snapshot.key" >>"$work/$name.log" 2>&1 &
  pid[$name]=$!
  local started=$(date +%s.%N)
  for _ in $(seq 100); do
    "$bin/nupmpc" --server "127.0.0.1:${port[$name]}" info >/dev/null 2>&1 && break
    sleep 0.1
  done
  "$bin/nupmpc" --server "127.0.0.1:${port[$name]}" info >/dev/null 2>&1 || fail "replica $name did not start"
  say "replica $name on port ${port[$name]} serving after $("$py" -c "import time; print(f'{time.time()-$started:.2f}')") s"
}
lb="127.0.0.1:$lb_port"
stats="$work/haproxy.sock"
haproxy_master=""
start_balancer() {  # replica names...: starts HAProxy, or reloads it with these replicas
  local addrs=()
  for n in "$@"; do addrs+=("127.0.0.1:${port[$n]}"); done
  deploy/haproxy/haproxy-config.sh --listen "$lb" --stats "$stats" "${addrs[@]}" > "$work/haproxy.cfg.new"
  haproxy -c -q -f "$work/haproxy.cfg.new" || fail "haproxy rejected the generated configuration"
  mv "$work/haproxy.cfg.new" "$work/haproxy.cfg"
  if [ -z "$haproxy_master" ]; then
    haproxy -W -db -f "$work/haproxy.cfg" >>"$work/haproxy.log" 2>&1 &
    haproxy_master=$!
  else
    kill -USR2 "$haproxy_master"  # master-worker reload: a new worker, the old one finishes its streams
  fi
  wait_up "$@"
}
server_line() { "$py" deploy/haproxy/haproxy-stat.py "$stats" streams 2>/dev/null | awk -v s="$1" '$1 == s'; }
field() { server_line "$1" | awk -v f="$2" '{print $f}'; }  # 2 status, 3 current, 4 total, 5 last check
wait_up() {  # replica names (r1, r2, ...): waits until the balancer has them all UP
  for _ in $(seq 100); do
    local all=1
    for n in "$@"; do [ "$(field "$n" 2)" = UP ] || all=0; done
    [ $all = 1 ] && return 0
    sleep 0.1
  done
  "$py" deploy/haproxy/haproxy-stat.py "$stats" streams >&2
  fail "the balancer did not see $* UP"
}
wait_streams_on() {  # replica: until it holds an open stream
  for _ in $(seq 200); do [ "$(field "$1" 3)" -ge 1 ] 2>/dev/null && return 0; sleep 0.05; done
  fail "replica $1 got no stream"
}

say "3 replicas and HAProxy ($(haproxy -v | head -1 | awk '{print $3}')) on $lb"
for n in r1 r2 r3; do start_replica "$n"; done
start_balancer r1 r2 r3

# 1. Spread and the proxy hop. The open streams per replica are read while the load runs.
lt=("$bin/nupmpc-loadtest" --instance "$instance" --echo=false --json --baseline_rounds 2 --transport_calls 200
    --warmup_s 0.5)
"${lt[@]}" --server "$lb" --concurrency "$streams" --duration_s "$phase_s" > "$work/spread.json" 2>"$work/loadtest.log" &
loadtest_pid=$!
declare -A most=([r1]=0 [r2]=0 [r3]=0)  # the most streams each replica held at once
while kill -0 "$loadtest_pid" 2>/dev/null; do
  for n in r1 r2 r3; do
    now=$(field "$n" 3)
    [ "${now:-0}" -gt "${most[$n]}" ] && most[$n]=$now
  done
  sleep 0.2
done
wait "$loadtest_pid" || fail "loadtest through the balancer"
out=$(cat "$work/spread.json")
say "spread: most open Control streams per replica during the load test: r1 ${most[r1]}, r2 ${most[r2]}, r3 ${most[r3]}"
for n in r1 r2 r3; do [ "${most[$n]}" -ge 1 ] || fail "replica $n held no stream; the load test said: $out"; done
level=$("$py" -c "import json,sys; print(json.dumps(json.loads(sys.argv[1])['levels'][0]))" "$out")
errors=$("$py" -c "import json,sys; print(json.loads(sys.argv[1])['errors'])" "$level")
[ "$errors" = "{}" ] || fail "loadtest through the balancer had errors: $errors"
"$py" - "$level" <<'PY'
import json, sys
l = json.loads(sys.argv[1])
print(f"== scaleout: through the balancer, {l['concurrency']} streams: {l['solves_per_s']:.0f} solves/s, "
      f"p50 {l['p50_ms']:.3f} ms, p99 {l['p99_ms']:.3f} ms")
PY
one_lb=$("${lt[@]}" --server "$lb" --concurrency 1 --duration_s "$phase_s") || fail "loadtest, 1 stream, balancer"
one_direct=$("${lt[@]}" --server "127.0.0.1:${port[r1]}" --concurrency 1 --duration_s "$phase_s") ||
  fail "loadtest, 1 stream, direct"
"$py" - "$one_lb" "$one_direct" <<'PY'
import json, sys
b, d = (json.loads(a)["levels"][0] for a in sys.argv[1:3])
print(f"== scaleout: 1 stream, balancer: {b['solves_per_s']:.0f} solves/s, p50 {b['p50_ms']:.3f} ms, p99 {b['p99_ms']:.3f} ms;"
      f" direct: {d['solves_per_s']:.0f} solves/s, p50 {d['p50_ms']:.3f} ms, p99 {d['p99_ms']:.3f} ms;"
      f" the hop adds {1000 * (b['p50_ms'] - d['p50_ms']):.0f} us at p50")
PY

# 1b. Debian's Prometheus scraping the three replicas with the alert rules of
#     deploy/prometheus/: every replica up, its metrics stored, the recorded deadline-miss
#     ratio evaluated for each (one query each, once scrapes have come in).
sed -e "s|127.0.0.1:9461\", \"127.0.0.1:9462\", \"127.0.0.1:9463|127.0.0.1:$m1\", \"127.0.0.1:$m2\", \"127.0.0.1:$m3|" \
  -e "s|scrape_interval: 5s|scrape_interval: 1s|; s|evaluation_interval: 5s|evaluation_interval: 1s|" \
  -e "s|  - nupmpc-alerts.yml|  - $PWD/deploy/prometheus/nupmpc-alerts.yml|" \
  deploy/prometheus/prometheus.yml > "$work/prometheus.yml"
prometheus --config.file="$work/prometheus.yml" --storage.tsdb.path="$work/tsdb" \
  --web.listen-address="127.0.0.1:$prom_port" --log.level=warn >>"$work/prometheus.log" 2>&1 &
prometheus_pid=$!
prom_query() {  # PromQL: prints the number of series and their values, or nothing yet
  "$py" - "127.0.0.1:$prom_port" "$1" <<'PY'
import json, sys, urllib.parse, urllib.request
try:
    url = f"http://{sys.argv[1]}/api/v1/query?" + urllib.parse.urlencode({"query": sys.argv[2]})
    result = json.load(urllib.request.urlopen(url, timeout=2))["data"]["result"]
    print(len(result), " ".join(sorted(r["value"][1] for r in result)))
except Exception:
    pass
PY
}
scraped=""
for _ in $(seq 100); do
  scraped=$(prom_query 'up{job="nupmpc"} == 1')
  recorded=$(prom_query 'nupmpc:step_deadline_miss_ratio:rate5m')
  [ "${scraped%% *}" = 3 ] && [ "${recorded%% *}" = 3 ] && break
  sleep 0.2
done
say "prometheus: replicas up: ${scraped:-none}; deadline-miss ratio recorded for: ${recorded:-none}"
[ "${scraped%% *}" = 3 ] || fail "prometheus did not scrape the three replicas (up: ${scraped:-none})"
[ "${recorded%% *}" = 3 ] || fail "prometheus did not evaluate the recording rule for the three replicas"
solves=$(prom_query 'sum(nupmpc_solves_total)')
[ "${solves#1 }" != "0" ] && [ -n "$solves" ] || fail "prometheus stored no solves (${solves:-nothing})"
kill "$prometheus_pid" 2>/dev/null; wait "$prometheus_pid" 2>/dev/null || true

# 2. Calls addressed by session id.
out=$("$bin/nupmpc-scaleout-probe" --server "$lb" --instance "$instance" --probe addressed --sessions 50 --solves 20) ||
  fail "addressed probe"
say "addressed: $out"
check() { "$py" -c "import json,sys; d=json.loads(sys.argv[1]); sys.exit(0 if ($2) else 1)" "$1" || fail "$3: $1"; }
check "$out" 'd["failed"] == 0 and d["recreated"] == 0 and d["miscounted"] == 0 and d["solves"] == 1000' \
  "a call addressed by session id missed its session"

# 3. Failover: kill -9 one replica under load.
# Streams of every session kind (loadtest/instances/session_kinds.h), so that a failover or
# a drain meets each.
probe=("$bin/nupmpc-scaleout-probe" --server "$lb" --instance "$instance" --probe streams --streams "$streams"
       --verify_every 10 --kinds "convex,input differences,keep-out,binary inputs")
# Each probe steps until its scenario is done (SIGTERM ends it; its duration only bounds a
# hung run), however slow the machine.
"${probe[@]}" --duration_s 600 > "$work/failover.json" 2>"$work/probe.log" &
probe_pid=$!
sleep "$("$py" -c "print($phase_s / 3)")"
wait_streams_on r1
held=$(field r1 3)
kill -0 "$probe_pid" 2>/dev/null || fail "failover: the probe ended before the kill"
kill -9 "${pid[r1]}"
say "killed replica r1 (SIGKILL) while it held $held streams"
sleep "$("$py" -c "print(2 * $phase_s / 3 + 4)")"  # the streams get their sessions back and step on
kill -TERM "$probe_pid"
wait "$probe_pid" || fail "streams probe (failover)"
out=$(cat "$work/failover.json")
say "failover: $out"
# The bar: at most one failed step per affected stream, reported as an error. The client
# library resends the step a dead replica swallowed, so normally none fails (the figure).
check "$out" 'd["affected_streams"] >= 1 and d["max_failed_per_affected_stream"] <= 1 and d["mismatched"] == 0 and d["verified"] > 0' \
  "failover: a stream failed more than one step, or a plan differs from the core's"
check "$out" 'd["recreated"] >= 1 and d["reattached"] == 0 and d["twin_mismatched"] == 0 and d["twin_compared"] > 0' \
  "failover: a session came back other than re-created cold, or a plan differs from its (re-created) twin's"
start_replica r1
wait_up r1 r2 r3

# 4. Drain: SIGTERM to one replica under load; the streams run on past its drain delay, so
# those it held must move.
"${probe[@]}" --duration_s 600 > "$work/drain.json" 2>>"$work/probe.log" &
probe_pid=$!
sleep "$("$py" -c "print($phase_s / 3)")"
wait_streams_on r2
held=$(field r2 3)
kill -TERM "${pid[r2]}"
drain_start=$(date +%s.%N)
for _ in $(seq 100); do [ "$(field r2 2)" = UP ] || break; sleep 0.05; done
# Taken out by its NOT_SERVING answer while it still runs (not by a refused connection).
kill -0 "${pid[r2]}" 2>/dev/null || fail "drain: replica r2 exited before the balancer took it out"
[ "$(field r2 2)" != UP ] || fail "drain: the balancer kept replica r2 UP"
say "SIGTERM to replica r2: the balancer took it out after" \
    "$("$py" -c "import time; print(f'{time.time()-$drain_start:.2f}')") s (last check $(field r2 5)," \
    "drain delay $drain_delay_s s)"
wait "${pid[r2]}" || fail "replica r2 did not exit 0 after SIGTERM"
sleep "$("$py" -c "print($phase_s / 3 + 1)")"  # the moved streams step on where they re-attached
kill -TERM "$probe_pid"
wait "$probe_pid" || fail "streams probe (drain)"
out=$(cat "$work/drain.json")
say "drain: $out"
check "$out" 'd["failed_steps"] == 0 and d["mismatched"] == 0 and d["affected_streams"] >= 1' "drain: a step failed"
# Bumpless: every stream r2 held got its session back by id, none cold, and every plan
# (the first after the move included) equals the never-moved twin's.
check "$out" "d['reattached'] >= $held and d['recreated'] == 0" \
  "drain: r2 held $held streams, not all of them re-attached (or a session was re-created)"
check "$out" 'd["twin_mismatched"] == 0 and d["twin_compared"] > 0' "drain: a plan differs from its never-moved twin's"
"$py" - "$out" "$held" <<'PY'
import json, sys
d = json.loads(sys.argv[1])
print(f"== scaleout: drain moved the sessions of {sys.argv[2]} streams: {d['reattached']} re-attached, "
      f"{d['recreated']} re-created, {d['failed_steps']} failed steps, {d['twin_compared']} plans compared with "
      f"never-moved twins, {d['twin_mismatched']} differing; first step after the move, per kind:")
for kind, how in sorted(d["first_steps_after_move"].items()):
    for way, f in how.items():
        print(f"==   {kind:17s} {way}: {f['moved']} moved, {f['same_as_twin']} equal to the twin, passes "
              f"{f['passes']} (twin {f['twin_passes']}); a cold re-create would take {f['cold_passes']} passes, "
              f"the twin's plan and passes {f['cold_same_as_twin']} times, max |u - u_twin| "
              f"{f['cold_max_difference']:.3g}")
PY
start_replica r2

# 5. Scale-up: a fourth replica, a balancer reload, new streams.
start_replica r4
start_balancer r1 r2 r3 r4
before_r4=$(field r4 4)
out=$("$bin/nupmpc-scaleout-probe" --server "$lb" --instance "$instance" --probe streams --streams 8 --duration_s 2) ||
  fail "streams probe (scale-up)"
got=$(( $(field r4 4) - before_r4 ))
say "scale-up: replica r4 got $got of 8 new streams; $out"
[ "$got" -gt 0 ] || fail "scale-up: the new replica got no stream"
check "$out" 'd["failed_steps"] == 0 and d["twin_mismatched"] == 0' "scale-up: a step failed, or a plan differs from its twin's"

# 6. The same in containers (full run only, where podman and the images are here): the
#    compose stack's smoke test (podman kube play).
if [ $quick = 0 ]; then
  if command -v podman >/dev/null && podman image exists localhost/nupmpc:latest 2>/dev/null &&
     podman image exists localhost/nupmpc-haproxy:latest 2>/dev/null &&
     podman image exists localhost/nupmpc-prometheus:latest 2>/dev/null; then
    stubs="${NUPMPC_PYTHON_STUBS:-build/python}"
    [ -f "$stubs/nupmpc/v1/nupmpc_pb2.py" ] || deploy/build.sh nupmpc_python
    say "compose stack (podman kube play): deploy/compose/smoke.sh, secure and --plaintext"
    NUPMPC_BIN_DIR="$bin" NUPMPC_PYTHON_STUBS="$stubs" deploy/compose/smoke.sh \
      --port "$("$py" tests/util/loopback_port.py)" || fail "the compose stack's smoke test"
    NUPMPC_BIN_DIR="$bin" deploy/compose/smoke.sh --plaintext --port "$("$py" tests/util/loopback_port.py)" ||
      fail "the compose stack's smoke test (--plaintext)"
  else
    say "compose stack: not run (needs podman and the images of deploy/container/build-image.sh," \
        "deploy/compose/build-balancer-image.sh and deploy/compose/build-prometheus-image.sh)"
  fi
fi
say "all checks passed"
