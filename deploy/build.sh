#!/usr/bin/env bash
# Installs dependencies (if missing) and builds into build/ (executables in build/bin/).
#   deploy/build.sh [TARGET...]     only these targets (default: everything)
# NUPMPC_CPU_BASELINE=x86-64|x86-64-v2|x86-64-v3|x86-64-v4|native chooses the instructions
# the build may use (default: x86-64-v3 where this machine has it, see deploy/README.md). The
# choice is kept in build/ and every later build uses it until it is given again.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${NUPMPC_NATIVE:-}" ]; then
  echo "deploy/build.sh: NUPMPC_NATIVE is no longer read; use NUPMPC_CPU_BASELINE=native" \
       "(tuned for this machine) or NUPMPC_CPU_BASELINE=x86-64-v3 (the portable default)" >&2
  exit 2
fi
deploy/install-deps.sh
if [ ! -f build/CMakeCache.txt ] || [ -n "${NUPMPC_CPU_BASELINE:-}" ]; then
  configure=(cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release)
  [ -n "${NUPMPC_CPU_BASELINE:-}" ] && configure+=(-DNUPMPC_CPU_BASELINE="$NUPMPC_CPU_BASELINE")
  log=$(mktemp)
  if ! "${configure[@]}" >"$log" 2>&1; then cat "$log" >&2; rm -f "$log"; exit 1; fi
  grep -E "^-- (CPU baseline|This machine lacks)" "$log" || true
  rm -f "$log"
fi
targets=()
for t in "$@"; do targets+=(--target "$t"); done
cmake --build build -j "$(nproc)" "${targets[@]}"
