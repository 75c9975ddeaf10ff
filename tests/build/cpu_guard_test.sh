#!/usr/bin/env bash
# The start-up guard (core/platform/cpu_baseline_guard.cc) refuses to run a program whose
# build uses an extension this CPU lacks, before main, naming it (exit 78), and lets a
# program whose extensions the CPU has run. The missing extension is simulated with a name
# the CPU cannot have; everything else is the guard as every program links it.
#   cpu_guard_test.sh CXX SOURCE_DIR
set -euo pipefail
cxx=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$cxx" -std=c++20 -march=x86-64 -I"$src" -c "$src/core/platform/cpu_baseline_guard.cc" -o "$work/guard.o"
echo 'int main() { return 0; }' >"$work/main.cc"
program() {  # features
  cat >"$work/data.cc" <<CC
namespace nupmpc::platform {
extern const char kBuildCpuBaseline[] = "test-level";
extern const char kBuildCpuFeatures[] = "$1";
}
CC
  "$cxx" -std=c++20 "$work/main.cc" "$work/data.cc" "$work/guard.o" -o "$work/program"
}
program " sse3 ssse3"
"$work/program" || { echo "FAIL: refused on a CPU with every extension the build uses" >&2; exit 1; }
program " sse3 no-such-extension"
set +e
message=$("$work/program" 2>&1)
status=$?
set -e
[ "$status" -eq 78 ] || { echo "FAIL: exit $status, expected 78; said: $message" >&2; exit 1; }
grep -q "lacks: no-such-extension (NUPMPC_CPU_BASELINE=test-level)" <<<"$message" ||
  { echo "FAIL: the message does not name the missing extension: $message" >&2; exit 1; }
echo "ok: $message"
