#!/usr/bin/env bash
# The sanitizer suite, run by deploy/test.sh (so by CI) after the main suite: an
# AddressSanitizer + UndefinedBehaviorSanitizer build in build-asan/ running the core and
# server tests; any finding fails the run.
#   * Compiled for x86-64-v3 with Eigen's alignment raised to 64 bytes (what AVX-512 builds
#     use): the aligned-allocation path on which AVX-512 servers crashed (issue 17) runs
#     under ASan whatever CPU the tests run on.
#   * -O1 with Eigen's assertions on; compiler warnings are errors.
#   * UBSan without its alignment, null, object-size, pointer-overflow, bounds and vptr
#     checks: they double the compile time of Eigen-heavy files (which would take CI past
#     its 30 minutes), and ASan already catches out-of-bounds and null accesses; a
#     misaligned Eigen access faults by itself under AVX.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install-deps.sh
echo "== sanitizer suite: AddressSanitizer + UndefinedBehaviorSanitizer (build-asan/)"
if [ ! -f build-asan/CMakeCache.txt ]; then
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
    -DNUPMPC_SANITIZE=address,undefined \
    -DNUPMPC_CPU_BASELINE=x86-64-v3 -DNUPMPC_WERROR=ON \
    "-DCMAKE_CXX_FLAGS=-DEIGEN_MAX_ALIGN_BYTES=64 -fno-sanitize=alignment,null,object-size,pointer-overflow,bounds,vptr" \
    >/dev/null
fi
cmake --build build-asan -j "$(nproc)"
export ASAN_OPTIONS=detect_leaks=1:detect_stack_use_after_return=1:strict_init_order=1:check_initialization_order=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export LSAN_OPTIONS=suppressions=$PWD/tests/sanitizers/lsan.supp
cd build-asan
ctest --output-on-failure -j "$(nproc)" --timeout 1200 -LE build
