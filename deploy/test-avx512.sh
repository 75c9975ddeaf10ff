#!/usr/bin/env bash
# The AVX-512 stage, run by deploy/test.sh (so by CI) after the main suite: the core's
# suites built for x86-64-v4 (AVX-512: Eigen's 64-byte
# packets and alignment, GCC's AVX-512 code) in build-avx512/, Release, warnings as errors.
# The tests run only on a CPU with AVX-512 (F, BW, CD, DQ, VL: what x86-64-v4 requires;
# the build's executables refuse to start elsewhere). On any other CPU the build and its
# warning check still run, and the script says plainly that the tests did not: a line
# "SKIPPED: reason" and exit code 77, which deploy/test.sh reports as SKIPPED, never as passed.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install-deps.sh
jobs=$(nproc)
# PRE_TEST: GoogleTest lists a binary's tests when ctest runs, not right after linking it
# (the default runs every test binary at build time, which a CPU without AVX-512 refuses).
# A unity build, as the sanitizer trees (deploy/sanitizer-tree.sh says why).
cmake -S . -B build-avx512 -G Ninja -DCMAKE_BUILD_TYPE=Release -DNUPMPC_CPU_BASELINE=x86-64-v4 \
  -DNUPMPC_WERROR=ON -DCMAKE_UNITY_BUILD=ON -DCMAKE_GTEST_DISCOVER_TESTS_DISCOVERY_MODE=PRE_TEST >/dev/null
# The suites whose code AVX-512 changes: the solver's kernels at every compiled state size
# and its memory (footprint, no allocation in the loop, Eigen's 64-byte alignment), the
# algorithms against the benchmark references, sessions and updates. The other suites run
# the same kernels, and the service's (with every other suite) run in the main suite and
# under ASan with Eigen's 64-byte alignment; this set keeps the stage to a few minutes of
# CI (building the service's library for x86-64-v4 as well doubled it).
core_tests=(message_passing_test session_test benchmark_reference_test interior_point_test footprint_test
            no_allocation_test step_update_test model_update_test)
targets=()
for t in "${core_tests[@]}"; do targets+=(--target "$t"); done
cmake --build build-avx512 -j "$jobs" "${targets[@]}"

missing=()
for flag in avx512f avx512bw avx512cd avx512dq avx512vl; do
  grep -qw "$flag" /proc/cpuinfo || missing+=("$flag")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "== AVX-512 stage: built for x86-64-v4 without warnings; tests NOT RUN: this CPU lacks ${missing[*]}"
  echo "SKIPPED: tests not run, this CPU lacks ${missing[*]} (built for x86-64-v4 without warnings)"
  exit 77
fi
echo "== AVX-512 stage: running the x86-64-v4 build's tests on this AVX-512 CPU"
# The tests of targets not built above show up as <target>_NOT_BUILT. Labels build (checks
# of the sources) and deploy (real processes from build/); PythonClient.*, PythonExample.*:
# the Python client's stubs are not built here.
cd build-avx512
ctest --output-on-failure -j "$(( jobs * 2 ))" --timeout 1200 -LE "build|deploy" \
  -E "_NOT_BUILT$|^Python(Client|Example)\\."
