#!/usr/bin/env bash
# The README's test command (and CI's): installs and builds what is missing, then runs every
# stage, each under a header, even when an earlier one failed, and ends with a table of
# every stage's result, counts and time. Exits 1 if any stage failed.
#   dependencies   deploy/install-deps.sh (every package and program the suite uses)
#   build          deploy/build.sh (build/)
#   main suite     ctest in build/
#   AVX-512        deploy/test-avx512.sh          NUPMPC_AVX512=0 skips it
#   ASan+UBSan     deploy/test-sanitizers.sh asan NUPMPC_SANITIZERS=0 skips the three
#   fuzzing        deploy/test-sanitizers.sh fuzz   sanitizer stages (a quick local run:
#                                                   24 s per target; NUPMPC_FUZZ_SECONDS)
#   TSan           deploy/test-sanitizers.sh tsan
# A stage skipped by design (the variables above; AVX-512 tests on a CPU without AVX-512,
# which its script reports with exit code 77 and a "SKIPPED: reason" line) is SKIPPED and
# does not fail the run; a stage that could not run (its build failed, a tool is missing)
# is FAILED. Every stage's output is shown and kept in build/test-logs/STAGE.log.
set -uo pipefail
cd "$(dirname "$0")/.."
logs=build/test-logs
mkdir -p "$logs"

names=() results=() times=() counts=()

# record NAME RESULT SECONDS COUNTS
record() {
  names+=("$1") results+=("$2") times+=("$(printf '%d:%02d' $(($3 / 60)) $(($3 % 60)))") counts+=("$4")
}

# counts_of LOG: what a stage's log says it ran (ctest's, libFuzzer's and the TSan triage's
# own summary lines), in one line.
counts_of() {
  local log=$1 parts=() line
  while read -r line; do
    parts+=("$(sed -E 's/.* ([0-9]+) tests failed out of ([0-9]+)/\2 tests, \1 failed/' <<<"$line")")
  done < <(grep -E "tests passed, [0-9]+ tests failed out of [0-9]+" "$log")
  if grep -qE "^[a-z_]+_fuzzer +[0-9]+ executions" "$log"; then
    parts+=("$(awk '/^[a-z_]+_fuzzer +[0-9]+ executions/ { t++; e += $2; f += $(NF-1) }
                    END { printf "%d targets, %d executions, %d findings", t, e, f }' "$log")")
  fi
  line=$(grep -E "^tsan triage: [0-9]+ findings" "$log" | tail -1)
  [ -n "$line" ] && parts+=("TSan: ${line#tsan triage: }")
  line=$(grep -E "^tsan triage: [0-9]+ reports NOT JUDGED" "$log" | tail -1)
  [ -n "$line" ] && parts+=("${line#tsan triage: }")
  local IFS=';'
  echo "${parts[*]:-}" | sed 's/;/; /g'
}

# stage NAME COMMAND...: runs it under a header, its output shown and logged.
stage() {
  local name=$1 log="$logs/$(tr ' +' '_' <<<"${1,,}").log" start=$SECONDS code
  shift
  echo
  echo "==================== stage: $name ===================="
  "$@" 2>&1 | tee "$log"
  code=${PIPESTATUS[0]}
  local elapsed=$((SECONDS - start)) summary
  summary=$(counts_of "$log")
  if [ "$code" -eq 0 ]; then
    record "$name" passed "$elapsed" "$summary"
  elif [ "$code" -eq 77 ]; then
    record "$name" SKIPPED "$elapsed" "$(grep -E "^SKIPPED: " "$log" | tail -1 | sed 's/^SKIPPED: //')"
  else
    record "$name" FAILED "$elapsed" "exit $code${summary:+; $summary} (log: $log)"
  fi
  echo "==================== $name: ${results[-1]} (${times[-1]})"
}

# skip NAME REASON / not_run NAME REASON
skip() { echo; echo "==================== stage: $1: SKIPPED ($2)"; record "$1" SKIPPED 0 "$2"; }
not_run() { echo; echo "==================== stage: $1: FAILED, not run ($2)"; record "$1" FAILED 0 "not run: $2"; }

main_suite() {
  cd build || return 1
  # Twice as many tests as CPUs: many of them mostly wait (servers, balancers, timeouts).
  ctest --output-on-failure -j "$(( $(nproc) * 2 ))" --timeout 1200
}

stage dependencies deploy/install-deps.sh
stage build deploy/build.sh
if [ "${results[-1]}" = passed ]; then
  stage "main suite" main_suite
else
  not_run "main suite" "the build failed"
fi
if [ "${NUPMPC_AVX512:-1}" = 0 ]; then
  skip "AVX-512" "NUPMPC_AVX512=0"
else
  stage "AVX-512" deploy/test-avx512.sh
fi
# The whole run must stay within CI's half hour: the fuzzing stage is a short smoke here
# (deploy/fuzz.sh SECONDS runs longer campaigns).
export NUPMPC_FUZZ_SECONDS="${NUPMPC_FUZZ_SECONDS:-24}"
for s in "ASan+UBSan:asan" "fuzzing:fuzz" "TSan:tsan"; do
  if [ "${NUPMPC_SANITIZERS:-1}" = 0 ]; then
    skip "${s%%:*}" "NUPMPC_SANITIZERS=0"
  else
    stage "${s%%:*}" deploy/test-sanitizers.sh "${s#*:}"
  fi
done

echo
echo "==================== deploy/test.sh: summary"
printf '%-14s %-8s %7s  %s\n' stage result time counts
failed=0
for i in "${!names[@]}"; do
  printf '%-14s %-8s %7s  %s\n' "${names[$i]}" "${results[$i]}" "${times[$i]}" "${counts[$i]}"
  [ "${results[$i]}" = FAILED ] && failed=1
done
if [ "$failed" -ne 0 ]; then
  echo "deploy/test.sh: FAILED (see the stages above)"
  exit 1
fi
echo "deploy/test.sh: every stage passed or was skipped by design"
