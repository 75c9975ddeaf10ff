#!/bin/bash
# clang-tidy 14 (Debian 12's) with the repository's .clang-tidy on the C++ of server/,
# client/, cli/ and loadtest/ (not core/, tests/ or fuzz/), with BUILD_DIR's
# compile_commands.json (the top CMakeLists.txt exports it; the generated protobuf headers
# must have been built):
#   tidy_check.sh SOURCE_DIR BUILD_DIR              the files changed lately (below)
#   tidy_check.sh SOURCE_DIR BUILD_DIR --since REV  the files changed since REV
#   tidy_check.sh SOURCE_DIR BUILD_DIR --all        every .cc file (about 10 minutes on 2 cores)
# Exit 0 when clean, 1 listing each finding (or when clang-tidy-14, the compilation database
# or the generated headers are missing), 77 when the default mode cannot tell what changed
# (not a git checkout).
#
# Changed files: those of the commits since REV and of the work tree (uncommitted and new
# ones). A changed header is checked through its own .cc, or else the first of our .cc files
# that includes it (its findings are reported from any file that includes it). The default
# REV is the merge base with origin/main when HEAD has commits of its own; else HEAD~20: in
# CI's fresh clone of main, origin/main is HEAD itself and the merge base names nothing, so
# the last 20 commits stand in for "what changed lately". Parsing one of our files (gRPC,
# protobuf, Eigen) and running the checks takes 10 to 20 s of CPU, so at most
# NUPMPC_TIDY_MAX_FILES files (default 12: 1 to 2 minutes on 2 cores) are checked, the work
# tree's first and then each commit's from the newest; the rest are named as not checked.
# --all checks everything: run it after changing .clang-tidy, and now and then.
set -euo pipefail
usage="usage: tidy_check.sh SOURCE_DIR BUILD_DIR [--all | --since REV]"
source_dir=${1:?$usage}
build_dir=${2:?$usage}
mode=changed
rev=
case "${3:-}" in
  "") ;;
  --all) mode=all ;;
  --since)
    rev=${4:?$usage}
    ;;
  *)
    echo "$usage" >&2
    exit 2
    ;;
esac
max_files=${NUPMPC_TIDY_MAX_FILES:-12}
folders=(server client cli loadtest)

fail() {
  echo "tidy_check.sh: $*" >&2
  exit 1
}
clang_tidy=$(command -v clang-tidy-14 || true)
[[ -n "$clang_tidy" ]] || fail "clang-tidy-14 is missing (package clang-tidy-14; deploy/install-deps.sh installs it)"
source_dir=$(cd "$source_dir" && pwd -P)
[[ -f "$source_dir/.clang-tidy" ]] || fail "$source_dir/.clang-tidy is missing"
[[ -d "$build_dir" ]] || fail "no build tree at $build_dir"
build_dir=$(cd "$build_dir" && pwd -P)
database="$build_dir/compile_commands.json"
[[ -f "$database" ]] ||
  fail "$database is missing: configure the build with -DCMAKE_EXPORT_COMPILE_COMMANDS=ON"
# The paths the compilation database uses (the build's own, as CMake was given them).
cmake_binary_dir=$(sed -n 's/^nupmpc_BINARY_DIR:STATIC=//p' "$build_dir/CMakeCache.txt" 2>/dev/null || true)
cmake_source_dir=$(sed -n 's/^nupmpc_SOURCE_DIR:STATIC=//p' "$build_dir/CMakeCache.txt" 2>/dev/null || true)
cmake_binary_dir=${cmake_binary_dir:-$build_dir}
cmake_source_dir=${cmake_source_dir:-$source_dir}
[[ -f "$cmake_binary_dir/proto/gen/nupmpc/v1/nupmpc.pb.h" ]] ||
  fail "the generated protobuf headers are missing: cmake --build $build_dir --target nupmpc_proto"

# Our .cc files that the compilation database compiles, relative to the source folder.
mapfile -t compiled < <(sed -n 's/^ *"file": "\(.*\)",\{0,1\}$/\1/p' "$database" |
  sed -n "s#^$cmake_source_dir/##p" | grep -E "^(server|client|cli|loadtest)/.*\.cc$" | sort -u)
((${#compiled[@]} > 0)) || fail "$database compiles no file of ${folders[*]} under $cmake_source_dir"
is_compiled() {
  local f
  for f in "${compiled[@]}"; do [[ "$f" == "$1" ]] && return 0; done
  return 1
}

files=()
not_checked=()
if [[ "$mode" == all ]]; then
  files=("${compiled[@]}")
else
  cd "$source_dir"
  if ! git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    echo "SKIPPED: $source_dir is not a git checkout; tidy_check.sh $source_dir $build_dir --all checks every file"
    exit 77
  fi
  if [[ -z "$rev" ]]; then
    if base=$(git merge-base HEAD origin/main 2>/dev/null) && [[ "$base" != "$(git rev-parse HEAD)" ]]; then
      rev=$base
    elif git rev-parse -q --verify "HEAD~20^{commit}" >/dev/null; then
      rev=HEAD~20
    else  # a short or shallow history: all of it
      rev=$(git rev-list --max-parents=0 HEAD | tail -1)
    fi
  fi
  git rev-parse -q --verify "$rev^{commit}" >/dev/null || fail "no commit $rev"
  # Newest first: the work tree, then each commit since REV from the newest.
  mapfile -t changed < <({
    git diff --name-only HEAD -- "${folders[@]}"
    git ls-files --others --exclude-standard -- "${folders[@]}"
    git log --format= --name-only "$rev..HEAD" -- "${folders[@]}"
  } | awk 'NF && !seen[$0]++')
  for f in "${changed[@]}"; do
    [[ -f "$f" ]] || continue  # deleted since
    case "$f" in
      *.cc) unit=$f ;;
      *.h)
        unit=${f%.h}.cc
        if ! is_compiled "$unit"; then
          unit=$(grep -lF "#include \"$f\"" "${compiled[@]}" 2>/dev/null | head -1 || true)
        fi
        ;;
      *) continue ;;
    esac
    [[ -n "$unit" ]] && is_compiled "$unit" || continue
    already=0
    for g in "${files[@]}" "${not_checked[@]}"; do [[ "$g" == "$unit" ]] && already=1; done
    ((already)) && continue
    if ((${#files[@]} < max_files)); then files+=("$unit"); else not_checked+=("$unit"); fi
  done
  label=$rev
  [[ "$rev" =~ ^[0-9a-f]{40}$ ]] && label="$(git rev-parse --short "$rev")"
  echo "tidy_check.sh: the files changed since $label and in the work tree"
  if git diff --name-only "$rev" -- .clang-tidy | grep -q .; then
    echo "tidy_check.sh: .clang-tidy changed since $rev: run tidy_check.sh $source_dir $build_dir --all as well"
  fi
  if ((${#files[@]} == 0)); then
    echo "tidy_check.sh: no C++ file of ${folders[*]} changed; nothing to check"
    exit 0
  fi
fi

# Our headers, as the build sees them through its include roots
# (BUILD/include/server_rpc/server/rpc/x.h is server/rpc/x.h) and as sources; never the
# generated ones (BUILD/proto/gen/), core/'s or the system's.
quote() { sed 's/[][\.|$(){}?+*^]/\\&/g' <<<"$1"; }
header_filter="^($(quote "$cmake_source_dir")|$(quote "$cmake_binary_dir")/include/[a-z_]+)/(server|client|cli|loadtest)/.*\.h$"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
start=$SECONDS
echo "tidy_check.sh: clang-tidy-14 on ${#files[@]} files, $(nproc) at a time"
printf '%s\n' "${files[@]}" | sed "s#^#$cmake_source_dir/#" |
  xargs -d '\n' -P "$(nproc)" -I{} sh -c '
    out="$1/$(echo "$2" | tr / :).log"
    if ! "$3" -p "$4" --quiet --header-filter="$5" --extra-arg=-Wno-unknown-warning-option "$2" >"$out" 2>&1; then
      echo "$2" >>"$1/failed"
    fi' _ "$work" {} "$clang_tidy" "$build_dir" "$header_filter" || true

# Each finding once (a header's comes from every file that includes it), under the path of
# its source file.
findings=$(cat "$work"/*.log | grep -E '^/[^ ]+:[0-9]+:[0-9]+: (warning|error): ' |
  sed -E "s#^$cmake_binary_dir/include/[a-z_]+/#$cmake_source_dir/#; s#^$cmake_source_dir/##" | sort -u || true)
elapsed=$((SECONDS - start))
status=0
if [[ -n "$findings" ]]; then
  echo "$findings"
  echo "tidy_check.sh: $(wc -l <<<"$findings") findings in ${#files[@]} files (${elapsed} s);" \
    "details: clang-tidy-14 -p $build_dir FILE"
  status=1
elif [[ -f "$work/failed" ]]; then
  # clang-tidy failed without a finding (a crash, an unreadable database entry).
  while read -r f; do
    echo "tidy_check.sh: clang-tidy-14 failed on $f:" >&2
    tail -20 "$work/$(echo "$f" | tr / :).log" >&2
  done <"$work/failed"
  status=1
else
  echo "tidy_check.sh: ${#files[@]} files clean (${elapsed} s)"
fi
if ((${#not_checked[@]} > 0)); then
  echo "tidy_check.sh: ${#not_checked[@]} more changed files not checked (NUPMPC_TIDY_MAX_FILES=$max_files; --all checks them):"
  printf '  %s\n' "${not_checked[@]:0:20}"
  ((${#not_checked[@]} <= 20)) || echo "  and $((${#not_checked[@]} - 20)) more"
fi
exit $status
