# Sourced by deploy/test-sanitizers.sh and deploy/fuzz.sh. Sanitizer reports are judged by
# their stacks (tsan_triage.py dismisses a race by its frames' source paths; a crash is read
# by its frames), so no stage judges a report before it has shown that stacks are symbolized:
# without llvm-symbolizer (package llvm-14, which clang only recommends) every frame reads
# "<null>".
#   SANITIZER_SYMBOLIZER            the llvm-symbolizer beside the clang that builds the trees
#   sanitizer_options_symbolizer    ":external_symbolizer_path=..." for *SAN_OPTIONS
#   check_symbolizer address|thread builds tests/build/symbolizer_probe.cc with that sanitizer
#                                   and checks its printed stack names the probe's function and
#                                   file; otherwise says why and exits 1
clang_bin_dir=$(dirname "$(readlink -f "$(command -v clang++ || echo /nonexistent/clang++)")")
SANITIZER_SYMBOLIZER="$clang_bin_dir/llvm-symbolizer"
sanitizer_options_symbolizer=":external_symbolizer_path=$SANITIZER_SYMBOLIZER"

check_symbolizer() {
  local kind=$1 dir output
  if [ ! -x "$SANITIZER_SYMBOLIZER" ]; then
    echo "sanitizer stage: $SANITIZER_SYMBOLIZER is missing (package llvm-14; deploy/install-deps.sh" \
         "installs it): sanitizer stacks would read <null> and no report could be judged. Not run." >&2
    exit 1
  fi
  dir=$(mktemp -d)
  clang++ -fsanitize="$kind" -g1 -O1 tests/build/symbolizer_probe.cc -o "$dir/probe"
  output=$(ASAN_OPTIONS="detect_leaks=0$sanitizer_options_symbolizer" \
           TSAN_OPTIONS="${sanitizer_options_symbolizer#:}" "$dir/probe" 2>&1 || true)
  rm -rf "$dir"
  if ! grep -q "SymbolizerProbeFrame().*symbolizer_probe.cc:" <<<"$output"; then
    echo "sanitizer stage: stacks are not symbolized with $SANITIZER_SYMBOLIZER (-fsanitize=$kind);" \
         "no report could be judged. Not run. The probe printed:" >&2
    echo "$output" | head -5 >&2
    exit 1
  fi
  echo "sanitizer stage: stacks are symbolized ($SANITIZER_SYMBOLIZER, -fsanitize=$kind)"
}
