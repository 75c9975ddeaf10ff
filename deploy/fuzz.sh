#!/usr/bin/env bash
# Fuzzing (libFuzzer, clang from Debian): builds the targets of tests/fuzz/ in build-asan/
# (AddressSanitizer + UBSan, coverage instrumentation on every library: deploy/sanitizer-tree.sh)
# and runs each for SECONDS (default 60), as many at once as there are CPUs. Corpora are
# seeded from the fuzz seed problem and the benchmark instances (nupmpc-fuzz-seeds) and grow
# in build-asan/fuzz/corpus/ from run to run; a crash, a sanitizer report, a hang or a
# violated property (tests/fuzz/fuzz_limits.h) is kept in build-asan/fuzz/findings/ and fails the
# script. Prints per target: executions, coverage (edges), corpus size, findings.
#   deploy/fuzz.sh [SECONDS] [TARGET...]
#   targets: spec_solve_fuzzer step_fuzzer control_stream_fuzzer problem_file_fuzzer snapshot_fuzzer
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
[ $# -gt 0 ] && shift
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(spec_solve_fuzzer step_fuzzer control_stream_fuzzer problem_file_fuzzer snapshot_fuzzer)
benchmarks="${NUPMPC_BENCHMARKS:-benchmarks}"
deploy/install-deps.sh
source deploy/sanitizer-symbolizer.sh
check_symbolizer address
deploy/sanitizer-tree.sh asan
build_targets=(--target nupmpc-fuzz-seeds)
for t in "${targets[@]}"; do build_targets+=(--target "$t"); done
cmake --build build-asan -j "$(nproc)" "${build_targets[@]}"

work=build-asan/fuzz
seeds=$work/seeds
rm -rf "$seeds"
build-asan/bin/nupmpc-fuzz-seeds "$seeds" "$benchmarks"/*.json
mkdir -p "$work/findings"
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1$sanitizer_options_symbolizer
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1$sanitizer_options_symbolizer

# fuzz TARGET: one run; its log is $work/TARGET.log, its exit code the verdict.
fuzz() {
  local t=$1 name=${1%_fuzzer}
  mkdir -p "$work/corpus/$name"
  # -timeout: an input that runs 10 s is a hang (every input is bounded to milliseconds of
  # work); -rss_limit_mb: one input may not hold more than the server would admit.
  build-asan/bin/"$t" "$work/corpus/$name" "$seeds/$name" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 -artifact_prefix="$work/findings/$t-" \
    >"$work/$t.log" 2>&1
}

pids=()
for t in "${targets[@]}"; do
  echo "== $t: ${seconds} s"
  fuzz "$t" &
  pids+=($!)
  while [ "$(jobs -rp | wc -l)" -ge "$(nproc)" ]; do wait -n || true; done
done
failed=0
summary=()
for i in "${!targets[@]}"; do
  t=${targets[$i]}
  log=$work/$t.log
  if ! wait "${pids[$i]}"; then
    failed=1
    echo "$t: FOUND a failure (log: $log, inputs: $work/findings/$t-*)"
    grep -E "ERROR|fuzz property violated|runtime error|deadly signal|timeout" "$log" | head -5 || true
  fi
  executions=$(grep -oE "stat::number_of_executed_units: [0-9]+" "$log" | grep -oE "[0-9]+$" || echo 0)
  coverage=$(grep -oE "cov: [0-9]+" "$log" | tail -1 | grep -oE "[0-9]+" || echo 0)
  findings=$(find "$work/findings" -name "$t-*" | wc -l)
  summary+=("$(printf '%-22s %10s executions %7s edges %6s corpus inputs %3s findings' "$t" "$executions" \
    "$coverage" "$(find "$work/corpus/${t%_fuzzer}" -type f | wc -l)" "$findings")")
done
printf '%s\n' "${summary[@]}"
exit "$failed"
