#!/usr/bin/env bash
# The README's test command (and CI's): installs and builds if needed, runs the whole test
# suite, then the AVX-512 build's (deploy/test-avx512.sh; NUPMPC_AVX512=0 skips it) and the
# sanitizer suites (deploy/test-sanitizers.sh; NUPMPC_SANITIZERS=0 skips them for a quick
# local run).
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
# Twice as many tests as CPUs: many of them mostly wait (servers, balancers, timeouts).
(cd build && ctest --output-on-failure -j "$(( $(nproc) * 2 ))" --timeout 1200)
# The AVX-512 build (its tests run where the CPU has AVX-512; NUPMPC_AVX512=0 skips it).
if [ "${NUPMPC_AVX512:-1}" != 0 ]; then
  deploy/test-avx512.sh
fi
if [ "${NUPMPC_SANITIZERS:-1}" != 0 ]; then
  deploy/test-sanitizers.sh
fi
