#!/usr/bin/env bash
# The README's main job: install dependencies, build, start nupmpc-server in the
# background, run the masses_N30 closed loop against it through the nupmpc CLI (a Control
# stream; prints the applied control u[0] and the solve / round-trip time of every step),
# and stop the server (SIGTERM: it drains and exits 0).
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
benchmarks="${NUPMPC_BENCHMARKS:-../shared/benchmarks}"
address="${NUPMPC_ADDRESS:-127.0.0.1:50051}"

build/bin/nupmpc-server --address "$address" --log_level warn &
server_pid=$!
trap 'kill -TERM "$server_pid" 2>/dev/null || true' EXIT

# Wait until the server answers (at most ~10 s).
for _ in $(seq 100); do
  build/bin/nupmpc --server "$address" info >/dev/null 2>&1 && break
  sleep 0.1
done

build/bin/nupmpc --server "$address" closed-loop "$benchmarks/masses_N30.json"

kill -TERM "$server_pid"
wait "$server_pid"
trap - EXIT
echo "nupmpc-server stopped cleanly"
