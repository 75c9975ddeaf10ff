#!/usr/bin/env bash
# The load-test figures of the service: builds, starts nupmpc-server in the background on
# this machine, pinned to its own CPUs, and runs nupmpc-loadtest against it from the others:
#   1. closed loop, concurrency 1, 2, 8, 64 on masses_N30 (transport-bound, solve ~0.1 ms),
#      with new references every step at 1 and 8, and masses_N300 (solver-bound) at 1, 2,
#      8; every level also against the zero-work echo, the inline-solve echo and the bare
#      server (peers in child processes pinned to the server's CPUs, interleaved with nupmpc
#      in 3 rounds), with the ratios nupmpc/inline and nupmpc/bare;
#   2. the fleet path: 100 masses_N30 sessions per SolveFleet call against 100 streams,
#      then in 2 calls of 50 in flight at once;
#   3. overload: masses_N300 (a few ms per solve, so the generator can offer 10x what
#      the server can solve), open loop at 10x the core-alone capacity, then at half of
#      it (recovery), against a server that refuses work it could not start within 20 ms;
#   4. 10,000 idle sessions: server RSS with them, compacted, and after they are closed;
#   5. deadlines under mixed control periods, EDF against FIFO (deploy/deadline-sweep.py).
# Pinning: on a machine with 3 or more CPUs, the server gets CPUs 0-1 (two workers, as
# designed) and the generator the rest; on 2 CPUs, the server CPU 0 with one worker and
# the generator CPU 1; on 1 CPU, nothing is pinned. NUPMPC_SERVER_CPUS / NUPMPC_CLIENT_CPUS
# / NUPMPC_THREADS override.
# Extra arguments go to every nupmpc-loadtest call (e.g. --json, --duration_s 10).
# Exit status 3 (after everything ran): a closed-loop level starved a stream, one served
# under half or over twice the mean.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
benchmarks="${NUPMPC_BENCHMARKS:-benchmarks}"
address="${NUPMPC_ADDRESS:-127.0.0.1:50052}"
cpus=$(nproc)
if [ "$cpus" -ge 3 ]; then
  server_cpus=${NUPMPC_SERVER_CPUS:-0-1} client_cpus=${NUPMPC_CLIENT_CPUS:-2-$((cpus - 1))} threads=${NUPMPC_THREADS:-2}
elif [ "$cpus" -eq 2 ]; then
  server_cpus=${NUPMPC_SERVER_CPUS:-0} client_cpus=${NUPMPC_CLIENT_CPUS:-1} threads=${NUPMPC_THREADS:-1}
else
  server_cpus=${NUPMPC_SERVER_CPUS:-} client_cpus=${NUPMPC_CLIENT_CPUS:-} threads=${NUPMPC_THREADS:-2}
fi
pin=()
[ -n "$server_cpus" ] && pin=(taskset -c "$server_cpus")
echo "CPUs: server ${server_cpus:-all} (--threads $threads), load generator ${client_cpus:-all} (of $cpus)"

server_pid=""
trap '[ -n "$server_pid" ] && kill -TERM "$server_pid" 2>/dev/null || true' EXIT
start_server() {  # flags for nupmpc-server
  # A server already there would be measured instead (the new one refuses the port and exits).
  if build/bin/nupmpc --server "$address" info >/dev/null 2>&1; then
    echo "a server already answers on $address; stop it or set NUPMPC_ADDRESS" >&2
    exit 1
  fi
  "${pin[@]}" build/bin/nupmpc-server --address "$address" --threads "$threads" --log_level warn "$@" &
  server_pid=$!
  for _ in $(seq 100); do
    kill -0 "$server_pid" 2>/dev/null || break
    build/bin/nupmpc --server "$address" info >/dev/null 2>&1 && kill -0 "$server_pid" 2>/dev/null && return
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

loadtest=(build/bin/nupmpc-loadtest --server "$address" --server_cpus "$server_cpus" --client_cpus "$client_cpus" "$@")
# A level that starved a stream (nupmpc-loadtest's exit status 3) fails the script at the
# end, after every figure is printed; any other failure stops it at once.
starved=0
run_loadtest() {
  local rc=0
  "${loadtest[@]}" "$@" || rc=$?
  if [ "$rc" -eq 3 ]; then starved=1; elif [ "$rc" -ne 0 ]; then exit "$rc"; fi
}
start_server
echo "== closed loop, masses_N30 (transport-bound)"
run_loadtest --instance "$benchmarks/masses_N30.json" --sweep 1,2,8,64 --inline_solve --bare_solve
echo "== closed loop, masses_N30, new references every step"
run_loadtest --instance "$benchmarks/masses_N30.json" --sweep 1,8 --inline_solve --new_references --bare_solve
echo "== closed loop, masses_N300 (solver-bound)"
run_loadtest --instance "$benchmarks/masses_N300.json" --sweep 1,2,8 --inline_solve --bare_solve
echo "== fleet: 100 masses_N30 sessions per SolveFleet call, then 100 separate Control streams"
run_loadtest --instance "$benchmarks/masses_N30.json" --fleet 100 --echo=false
echo "== fleet: the same 100 sessions in 2 SolveFleet calls of 50 in flight at once (the server's throughput)"
run_loadtest --instance "$benchmarks/masses_N30.json" --fleet 100 --fleet_calls_in_flight 2 --echo=false
echo "== memory: 10,000 idle masses_N30 sessions"
run_loadtest --instance "$benchmarks/masses_N30.json" --idle_sessions 10000
stop_server

start_server --max_queue_wait_ms 20
echo "== overload, masses_N300 (server refuses work it could not start within 20 ms):"
echo "   open loop at 10x capacity, then at 0.5x (recovery)"
run_loadtest --instance "$benchmarks/masses_N300.json" --mode open --rate_x 10 --concurrency 64
run_loadtest --instance "$benchmarks/masses_N300.json" --mode open --rate_x 0.5 --concurrency 64
stop_server
echo "== deadlines: 32 masses_N30 streams at a short period and 8 masses_N300 at a long one, at 50-120 % of"
echo "   the core's capacity, EDF and FIFO servers in turn (deploy/deadline-sweep.py)"
NUPMPC_BENCHMARK_DIR="$benchmarks" /usr/bin/python3 deploy/deadline-sweep.py
if [ "$starved" -ne 0 ]; then
  echo "deploy/loadtest.sh: a level starved a stream (see nupmpc-loadtest's messages above)" >&2
  exit 3
fi
