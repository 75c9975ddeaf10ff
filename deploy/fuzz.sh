#!/usr/bin/env bash
# Fuzzing (libFuzzer, clang from Debian): builds the targets of fuzz/ in build-fuzz/ with
# AddressSanitizer + UBSan and coverage instrumentation on every library, seeds the corpora
# from the fuzz seed problem and the benchmark instances, and runs each target for SECONDS
# (default 60). The corpora grow in build-fuzz/corpus/ from run to run; a crash, a sanitizer
# report or a violated property (fuzz/fuzz_limits.h) is kept in build-fuzz/findings/ and
# fails the script. Prints per target: executions, coverage (edges), corpus size, findings.
#   deploy/fuzz.sh [SECONDS] [TARGET...]      targets: spec_solve_fuzzer step_fuzzer problem_file_fuzzer
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
[ $# -gt 0 ] && shift
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(spec_solve_fuzzer step_fuzzer problem_file_fuzzer)
benchmarks="${NUPMPC_BENCHMARKS:-../shared/benchmarks}"
deploy/install-deps.sh
if [ ! -f build-fuzz/CMakeCache.txt ]; then
  cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
    -DNUPMPC_SANITIZE=address,undefined -DNUPMPC_FUZZ=ON -DNUPMPC_BUILD_TESTS=OFF \
    -DNUPMPC_CPU_BASELINE=x86-64-v3 -DCMAKE_CXX_FLAGS=-DEIGEN_MAX_ALIGN_BYTES=64 >/dev/null
fi
build_targets=(--target nupmpc-fuzz-seeds)
for t in "${targets[@]}"; do build_targets+=(--target "$t"); done
cmake --build build-fuzz -j "$(nproc)" "${build_targets[@]}"

seeds=build-fuzz/seeds
rm -rf "$seeds"
build-fuzz/bin/nupmpc-fuzz-seeds "$seeds" "$benchmarks"/*.json
mkdir -p build-fuzz/findings
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
failed=0
summary=()
for t in "${targets[@]}"; do
  name="${t%_fuzzer}"
  corpus="build-fuzz/corpus/$name"
  mkdir -p "$corpus"
  log="build-fuzz/$t.log"
  echo "== $t: ${seconds} s"
  # -timeout: an input that runs 10 s is a hang (every input is bounded to milliseconds);
  # -rss_limit_mb: one input may not hold more than the server would admit.
  if ! build-fuzz/bin/"$t" "$corpus" "$seeds/$name" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
       -max_len=65536 -print_final_stats=1 -artifact_prefix="build-fuzz/findings/$t-" >"$log" 2>&1; then
    failed=1
    echo "$t: FOUND a failure (log: $log, inputs: build-fuzz/findings/$t-*)"
    grep -E "ERROR|fuzz property violated|runtime error|deadly signal|timeout" "$log" | head -5 || true
  fi
  executions=$(grep -oE "stat::number_of_executed_units: [0-9]+" "$log" | grep -oE "[0-9]+$" || echo 0)
  coverage=$(grep -oE "cov: [0-9]+" "$log" | tail -1 | grep -oE "[0-9]+" || echo 0)
  findings=$(find build-fuzz/findings -name "$t-*" | wc -l)
  summary+=("$(printf '%-22s %10s executions %7s edges %6s corpus inputs %3s findings' "$t" "$executions" \
    "$coverage" "$(find "$corpus" -type f | wc -l)" "$findings")")
done
printf '%s\n' "${summary[@]}"
exit "$failed"
