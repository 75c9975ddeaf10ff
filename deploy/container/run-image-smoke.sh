#!/usr/bin/env bash
# Smoke test of the nupmpc image: starts a container, measures the time to SERVING, runs
# `nupmpc info` inside it and a short closed loop through it, stops it with SIGTERM and checks
# that it exits 0 within the grace period. Prints the image size, the start-up time and the
# uid the server runs as. Exit status 0 only if every check passed.
#
# Usage: deploy/container/run-image-smoke.sh [IMAGE]      (default nupmpc:latest)
# Environment:
#   NUPMPC_HOST_CLI        the host's nupmpc for the closed loop (default build/bin/nupmpc;
#                          if missing, the CLI inside the container runs it)
#   NUPMPC_SMOKE_INSTANCE  closed-loop instance (default benchmarks/masses_N30.json)
#   NUPMPC_SMOKE_STEPS     closed-loop steps (default 20)
#   NUPMPC_GRACE_PERIOD_S  the server's drain grace (default 5); podman stop waits 5 s more
#   NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE   see podman-env.sh
# The container uses the host network (no bridge/CNI needed) on a free loopback port.
set -euo pipefail
cd "$(dirname "$0")/../.."
image=${1:-nupmpc:latest}
case "$image" in -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;; esac

nupmpc_podman_tag=smoke
# shellcheck source=deploy/container/podman-env.sh
. deploy/container/podman-env.sh
say() { echo "smoke: $*"; }
failures=()
fail() { say "FAIL: $*"; failures+=("$*"); }

nupmpc_podman_setup
"${podman_base[@]}" image exists "$image" || { say "no image $image (deploy/container/build-image.sh)"; exit 1; }
nupmpc_podman_runtime "$image"
say "image $image, runtime $NUPMPC_PODMAN_RUNTIME, storage $NUPMPC_PODMAN_STORAGE"

host_cli=${NUPMPC_HOST_CLI:-build/bin/nupmpc}
instance=${NUPMPC_SMOKE_INSTANCE:-benchmarks/masses_N30.json}
steps=${NUPMPC_SMOKE_STEPS:-20}
grace=${NUPMPC_GRACE_PERIOD_S:-5}
stop_timeout=$(awk -v g="$grace" 'BEGIN { printf "%d", g + 5.999 }')
now_ns() { date +%s%N; }
ms_between() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f", (b - a) / 1e6 }'; }

port=$(python3 tests/util/loopback_port.py)
address=127.0.0.1:$port
name=nupmpc-smoke-$$
cleanup() { "${podman_run[@]}" rm -f --time 0 "$name" >/dev/null 2>&1 || true; }
trap cleanup EXIT

# Readiness: grpc.health.v1.Health/Check with raw bytes (request: empty message; response
# 08 01: status SERVING) through Debian's python3-grpcio. The poller starts (and imports
# grpc, ~0.1 s) before `podman run`, and every attempt uses a fresh channel, so neither
# Python's start-up nor gRPC's reconnect back-off (1 s and growing) enters the measurement.
# Without python3-grpcio, the first successful `nupmpc info` (GetServerInfo) from inside
# the container stands in for SERVING.
health_py='
import sys, time
import grpc
print("ready", flush=True)
deadline = time.monotonic() + float(sys.argv[2])
while time.monotonic() < deadline:
    with grpc.insecure_channel(sys.argv[1]) as channel:
        try:
            if channel.unary_unary("/grpc.health.v1.Health/Check")(b"", timeout=0.25) == b"\x08\x01":
                print(time.time_ns(), flush=True); sys.exit(0)
        except grpc.RpcError:
            pass
    time.sleep(0.005)
sys.exit(1)
'
health_python=
for py in /usr/bin/python3 python3; do
  if "$py" -c 'import grpc' 2>/dev/null; then health_python=$py; break; fi
done
poll_out=$(mktemp)
poller=
trap 'cleanup; [ -z "$poller" ] || kill "$poller" 2>/dev/null; rm -f "$poll_out"' EXIT
if [ -n "$health_python" ]; then
  "$health_python" -c "$health_py" "$address" 30 >"$poll_out" &
  poller=$!
  until grep -q ready "$poll_out"; do sleep 0.01; done
fi
wait_serving() {  # sets t_serving: the wall-clock ns of the first SERVING answer
  if [ -n "$health_python" ]; then
    wait "$poller" || return 1
    poller=
    t_serving=$(tail -n 1 "$poll_out")
    return 0
  fi
  local end=$(( $(date +%s) + 30 ))
  while [ "$(date +%s)" -lt "$end" ]; do
    if "${podman_run[@]}" exec "$name" /usr/local/bin/nupmpc --server "$address" --deadline_ms 500 info >/dev/null 2>&1; then
      t_serving=$(now_ns); return 0
    fi
    sleep 0.02
  done
  return 1
}

# --- start ---------------------------------------------------------------------------------
t_run=$(now_ns)
"${podman_run[@]}" run -d --name "$name" --network host "${ulimits[@]}" \
  -e NUPMPC_ADDRESS="$address" -e NUPMPC_GRACE_PERIOD_S="$grace" "$image" >/dev/null
t_detached=$(now_ns)
if wait_serving; then
  startup_ms=$(ms_between "$t_run" "$t_serving")
  t_started=$("${podman_run[@]}" inspect --format '{{.State.StartedAt.UnixNano}}' "$name")
  process_ms=$(ms_between "$t_started" "$t_serving")
  # The server's own "listening" log line (spdlog's local time: UTC in the container)
  # separates the server's start-up from the poller's.
  listening=$("${podman_run[@]}" logs "$name" 2>&1 | sed -n 's/^\[\([0-9-]* [0-9:.]*\)\] \[info\] nupmpc-server .* listening on.*/\1/p' | head -n 1)
  listening_ms='?'
  [ -n "$listening" ] && listening_ms=$(ms_between "$t_started" "$(TZ=UTC date -d "$listening" +%s%N)")
  say "SERVING on $address ${startup_ms} ms after \`podman run\` (podman run itself $(ms_between "$t_run" "$t_detached") ms;" \
      "${process_ms} ms after the container process started, which logged 'listening' after ${listening_ms} ms)" \
      "$([ -n "$health_python" ] && echo '[grpc.health.v1]' || echo '[GetServerInfo]')"
else
  startup_ms=
  fail "not SERVING within 30 s"
  "${podman_run[@]}" logs "$name" 2>&1 | tail -n 20
  exit 1
fi

# --- who runs it ---------------------------------------------------------------------------
pid=$("${podman_run[@]}" inspect --format '{{.State.Pid}}' "$name")
host_uid=$(stat -c %u "/proc/$pid")
inside=$("${podman_run[@]}" exec "$name" id)
say "server process: host pid $pid, uid $host_uid on the host; inside: $inside"
if [ "$host_uid" = 0 ]; then fail "the server runs as root"; else nonroot="yes (uid $host_uid)"; fi

# --- inside: the CLI and the libraries -----------------------------------------------------
say "nupmpc info (the CLI inside the container):"
if ! "${podman_run[@]}" exec "$name" /usr/local/bin/nupmpc --server "$address" info | sed 's/^/  /'; then
  fail "nupmpc info inside the container"
fi
libs=$("${podman_run[@]}" exec "$name" ldd /usr/local/bin/nupmpc-server)
if grep -q 'not found' <<<"$libs"; then fail "unresolved libraries: $(grep 'not found' <<<"$libs" | tr '\n' ' ')"; fi
say "nupmpc-server: $(grep -c '=>' <<<"$libs") shared libraries, all resolved"

# --- a closed loop through it ----------------------------------------------------------------
if [ ! -f "$instance" ]; then
  fail "no instance $instance"
else
  if [ -x "$host_cli" ]; then
    say "closed loop: $host_cli --server $address closed-loop $instance --steps $steps (host CLI)"
    loop=("$host_cli" --server "$address" closed-loop "$instance" --steps "$steps")
  else
    say "closed loop: no host CLI at $host_cli, the container's CLI runs it"
    "${podman_run[@]}" cp "$instance" "$name:/tmp/instance.json"
    loop=("${podman_run[@]}" exec "$name" /usr/local/bin/nupmpc --server "$address" closed-loop /tmp/instance.json --steps "$steps")
  fi
  if ! "${loop[@]}" 2>&1 | sed 's/^/  /'; then fail "closed loop"; fi
fi

# --- SIGTERM -------------------------------------------------------------------------------
# Not `run --rm`: the exit code must survive the container's exit to be read here.
t_stop=$(now_ns)
"${podman_run[@]}" stop --time "$stop_timeout" "$name" >/dev/null
stop_ms=$(ms_between "$t_stop" "$(now_ns)")
exit_code=$("${podman_run[@]}" inspect --format '{{.State.ExitCode}}' "$name")
say "server log:"
"${podman_run[@]}" logs "$name" 2>&1 | sed 's/^/  /'
if [ "$exit_code" != 0 ]; then
  fail "exit code $exit_code after SIGTERM (137: killed after the ${stop_timeout} s stop timeout)"
fi
say "SIGTERM: exited $exit_code in ${stop_ms} ms (grace ${grace} s, podman stop --time ${stop_timeout})"

size=$("${podman_base[@]}" image inspect --format '{{.Size}}' "$image")
echo
echo "image              $image, $(awk -v s="$size" 'BEGIN { printf "%.1f", s / 1e6 }') MB"
echo "start-up           ${startup_ms} ms from podman run to SERVING (${process_ms} ms from process start)"
echo "non-root           ${nonroot:-no}"
echo "SIGTERM            exit $exit_code after ${stop_ms} ms"
if [ ${#failures[@]} -gt 0 ]; then
  echo "FAILED: ${failures[*]}"
  exit 1
fi
echo "smoke test passed"
