#!/usr/bin/env bash
# The README's main job: checks its prerequisites, installs dependencies and builds the
# two programs it runs, starts nupmpc-server in the background, runs the masses_N30
# closed loop against it through the nupmpc CLI (one Control stream; every step's applied
# control u[0], solve and round-trip time, then a summary), and stops the server with
# SIGTERM (it drains and exits 0).
set -euo pipefail
cd "$(dirname "$0")/.."
benchmarks="${NUPMPC_BENCHMARKS:-benchmarks}"
address="${NUPMPC_ADDRESS:-127.0.0.1:50051}"
instance="$benchmarks/masses_N30.json"

say() { echo "== $*"; }
if [ ! -f "$instance" ]; then
  echo "deploy/main.sh: $instance not found. The benchmark instances live in benchmarks/ of this checkout" \
       "(or set NUPMPC_BENCHMARKS to their folder)." >&2
  exit 1
fi

say "Building nupmpc-server and the nupmpc client (the first build takes several minutes)"
deploy/build.sh nupmpc-server nupmpc

# Another server answering there would be the one this session talks to (the new one
# refuses a port in use and exits).
if build/bin/nupmpc --server "$address" info >/dev/null 2>&1; then
  echo "deploy/main.sh: a server already answers on $address; stop it or set NUPMPC_ADDRESS" >&2
  exit 1
fi
build/bin/nupmpc-server --address "$address" --log_level warn &
server_pid=$!
trap 'kill -TERM "$server_pid" 2>/dev/null || true' EXIT
# Wait until the server answers (at most ~10 s).
for _ in $(seq 100); do
  build/bin/nupmpc --server "$address" info >/dev/null 2>&1 && break
  kill -0 "$server_pid" 2>/dev/null || { echo "deploy/main.sh: nupmpc-server exited at start-up" >&2; exit 1; }
  sleep 0.1
done
kill -0 "$server_pid" 2>/dev/null || { echo "deploy/main.sh: nupmpc-server exited at start-up" >&2; exit 1; }
say "nupmpc-server (pid $server_pid) listens on $address"

say "The plant: 6 masses in a chain between two walls, joined by springs (12 states), pushed" \
    "by 3 actuators with |u| <= 0.5, every state within |x| <= 4; a 30-step horizon (sample time 0.5)."
say "Closed loop: 100 control periods through one Control stream. Each period sends the measured" \
    "state (recorded in $instance) and gets back the optimal plan; the table shows the first" \
    "input u[0] applied, the server's solve time and the client's round trip."
build/bin/nupmpc --server "$address" closed-loop "$instance"

say "Stopping nupmpc-server (SIGTERM: it finishes what is running, then exits)"
kill -TERM "$server_pid"
wait "$server_pid"
trap - EXIT
echo "nupmpc-server stopped cleanly"
