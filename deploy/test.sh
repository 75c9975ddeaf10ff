#!/usr/bin/env bash
# The README's test command (and CI's): installs and builds if needed, runs the whole test
# suite, then the sanitizer suites (deploy/test-sanitizers.sh; NUPMPC_SANITIZERS=0 skips
# them for a quick local run).
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
# Twice as many tests as CPUs: many of them mostly wait (servers, balancers, timeouts).
(cd build && ctest --output-on-failure -j "$(( $(nproc) * 2 ))" --timeout 1200)
if [ "${NUPMPC_SANITIZERS:-1}" != 0 ]; then
  deploy/test-sanitizers.sh
fi
