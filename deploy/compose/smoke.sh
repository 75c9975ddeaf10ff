#!/usr/bin/env bash
# Smoke test of the compose stack: up.sh, then through the balancer on the host port
#   1. 12 Control streams for 5 s (nupmpc-scaleout-probe --probe streams): no failed step,
#      no plan that differs from the core's, and how HAProxy spread the streams;
#   2. 20 sessions by client-drawn id, each solved 10 times by id (--probe addressed): every
#      call reaches its session (none failed, none had to be re-created);
# then down.sh: every container exits 0 on SIGTERM. Exit status 0 only if all passed.
#
# Usage: deploy/compose/smoke.sh [--port P]          (default 50051)
# Environment:
#   NUPMPC_BIN_DIR       the host build with nupmpc-scaleout-probe (default build/bin)
#   NUPMPC_BENCHMARKS    instances (default benchmarks/; masses_N30.json is used)
#   NUPMPC_SERVER_IMAGE, NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE   see up.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
port=50051
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "smoke.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
probe=${NUPMPC_BIN_DIR:-build/bin}/nupmpc-scaleout-probe
instance=${NUPMPC_BENCHMARKS:-benchmarks}/masses_N30.json
[ -x "$probe" ] || { echo "smoke: no $probe (deploy/build.sh nupmpc-scaleout-probe, or set NUPMPC_BIN_DIR)" >&2; exit 1; }
[ -f "$instance" ] || { echo "smoke: no $instance (set NUPMPC_BENCHMARKS)" >&2; exit 1; }
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
deploy/compose/up.sh --port "$port"
nupmpc_podman_quiet=1 nupmpc_stack_setup
trap 'deploy/compose/down.sh || true' EXIT
server=127.0.0.1:$port

before=$(stack_servers streams)
streams=$("$probe" --server "$server" --instance "$instance" --probe streams --streams 12 --duration_s 5)
echo "smoke: streams: $streams"
echo "smoke: streams: Control streams per replica (HAProxy): $(spread streams "$before")"
check "$streams" 'd["failed_steps"] == 0 and d["mismatched"] == 0 and d["no_plan"] == 0 and d["verified"] > 0' \
  "streams: a step failed or a plan differs from the core's"

before=$(stack_servers pinned)
addressed=$("$probe" --server "$server" --instance "$instance" --probe addressed --sessions 20 --solves 10)
echo "smoke: addressed: $addressed"
echo "smoke: addressed: calls by id per replica (HAProxy): $(spread pinned "$before")"
check "$addressed" 'd["failed"] == 0 and d["recreated"] == 0 and d["miscounted"] == 0 and d["solves"] == 200' \
  "addressed: a call by session id missed its session"

trap - EXIT
deploy/compose/down.sh || failures+=("down: a container did not exit 0 on SIGTERM")
python3 - "$streams" <<'PY'
import json, sys
d = json.loads(sys.argv[1])
print(f"smoke: {d['streams']} streams through the balancer: {d['solves_per_s']:.0f} solves/s,"
      f" p50 {d['p50_ms']:.2f} ms, p99 {d['p99_ms']:.2f} ms")
PY
if [ ${#failures[@]} -gt 0 ]; then echo "smoke: FAILED: ${failures[*]}"; exit 1; fi
echo "smoke: compose stack passed"
