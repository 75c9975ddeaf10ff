#!/usr/bin/env bash
# The load-test figures of the service: builds, starts nupmpc-server in the background on
# this machine, and runs nupmpc-loadtest against it (server and load generator share the
# machine's cores: say so when you quote the figures):
#   1. closed loop, concurrency 1, 2, 8, 64 (masses_N30 closed-loop states), each level also
#      against the zero-work echo and the inline-solve echo (peers in child processes);
#   2. overload: masses_N300 (a few ms per solve, so the generator can offer 10x what
#      the server can solve), open loop at 10x the core-alone capacity, then at half of
#      it (recovery), against a server that refuses work it could not start within 20 ms;
#   3. 10,000 idle sessions: server RSS with them, compacted, and after they are closed.
# Extra arguments go to every nupmpc-loadtest call (e.g. --json, --duration_s 10).
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
benchmarks="${NUPMPC_BENCHMARKS:-../shared/benchmarks}"
address="${NUPMPC_ADDRESS:-127.0.0.1:50052}"

server_pid=""
trap '[ -n "$server_pid" ] && kill -TERM "$server_pid" 2>/dev/null || true' EXIT
start_server() {  # flags for nupmpc-server
  build/bin/nupmpc-server --address "$address" --log_level warn "$@" &
  server_pid=$!
  for _ in $(seq 100); do
    build/bin/nupmpc --server "$address" info >/dev/null 2>&1 && return
    sleep 0.1
  done
  echo "nupmpc-server did not come up on $address" >&2
  exit 1
}
stop_server() {
  kill -TERM "$server_pid"
  wait "$server_pid"
  server_pid=""
}

loadtest=(build/bin/nupmpc-loadtest --server "$address" "$@")
start_server
echo "== closed loop, masses_N30"
"${loadtest[@]}" --instance "$benchmarks/masses_N30.json" --sweep 1,2,8,64 --inline_solve
echo "== memory: 10,000 idle masses_N30 sessions"
"${loadtest[@]}" --instance "$benchmarks/masses_N30.json" --idle_sessions 10000
stop_server

start_server --max_queue_wait_ms 20
echo "== overload, masses_N300 (server refuses work it could not start within 20 ms):"
echo "   open loop at 10x capacity, then at 0.5x (recovery)"
"${loadtest[@]}" --instance "$benchmarks/masses_N300.json" --mode open --rate_x 10 --concurrency 64
"${loadtest[@]}" --instance "$benchmarks/masses_N300.json" --mode open --rate_x 0.5 --concurrency 64
stop_server
