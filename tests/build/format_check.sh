#!/bin/bash
# Every C++ source of the tree as .clang-format says (clang-format 14, Debian 12's):
#   format_check.sh SOURCE_DIR          exit 1 naming each file clang-format would change
#   format_check.sh SOURCE_DIR --fix    rewrite those files in place
# Build trees (build*/), hidden folders and benchmarks/ are not sources.
set -euo pipefail
source_dir=${1:?usage: format_check.sh SOURCE_DIR [--fix]}
mode=${2:-check}
clang_format=$(command -v clang-format-14 || command -v clang-format || true)
if [[ -z "$clang_format" ]]; then
  echo "format_check.sh: clang-format is missing (package clang-format; deploy/install-deps.sh installs it)" >&2
  exit 1
fi
cd "$source_dir"
mapfile -d '' files < <(find . \( -path './build*' -o -path './.*' -o -path './benchmarks' \) -prune -o \
  -type f \( -name '*.cc' -o -name '*.h' \) -print0 | sort -z)
if [[ "$mode" == "--fix" ]]; then
  "$clang_format" -i --style=file "${files[@]}"
  echo "format_check.sh: formatted ${#files[@]} files"
  exit 0
fi
unformatted=()
for f in "${files[@]}"; do
  if ! "$clang_format" --dry-run --Werror --style=file "$f" 2>/dev/null; then unformatted+=("${f#./}"); fi
done
if ((${#unformatted[@]} > 0)); then
  printf '%s: not as .clang-format says\n' "${unformatted[@]}"
  echo "format_check.sh: ${#unformatted[@]} of ${#files[@]} files; run tests/build/format_check.sh . --fix" >&2
  exit 1
fi
echo "format_check.sh: ${#files[@]} files, all formatted"
