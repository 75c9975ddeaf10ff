#!/usr/bin/env bash
# Configures a sanitizer build tree (cheap when it is configured already), for deploy/test-sanitizers.sh
# and deploy/fuzz.sh. Both trees are clang, compiled for x86-64-v3, -O1 with Eigen's
# assertions on, warnings as errors (CMakeLists.txt: NUPMPC_SANITIZE).
#   deploy/sanitizer-tree.sh asan    build-asan/: AddressSanitizer + UndefinedBehaviorSanitizer,
#        Eigen's alignment raised to 64 bytes (what AVX-512 builds use: the aligned-allocation
#        path whose misuse crashes AVX-512 servers, runs under ASan whatever CPU runs the
#        tests), and libFuzzer's coverage instrumentation, so the fuzz targets of tests/fuzz/ build
#        in the same tree as the tests (one sanitizer build in CI, not two).
#   deploy/sanitizer-tree.sh tsan    build-tsan/: ThreadSanitizer, the dynamic-size solver
#        kernels only (NUPMPC_FIXED_SIZE_KERNELS, core/message_passing/fixed_size.h).
set -euo pipefail
cd "$(dirname "$0")/.."
kind=${1:?usage: deploy/sanitizer-tree.sh asan|tsan}
# Unity builds (CMAKE_UNITY_BUILD): each library compiles as a few large translation units,
# so gRPC's, protobuf's and Eigen's headers are parsed once per batch, not once per file;
# these trees are built from scratch in every CI run. The main build (deploy/build.sh)
# compiles every file on its own, which keeps each one self-contained.
common=(-G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ -DNUPMPC_CPU_BASELINE=x86-64-v3
        -DNUPMPC_WERROR=ON -DCMAKE_UNITY_BUILD=ON)
case "$kind" in
  asan) dir=build-asan
        flags=(-DNUPMPC_SANITIZE=address,undefined -DNUPMPC_FUZZ=ON -DCMAKE_CXX_FLAGS=-DEIGEN_MAX_ALIGN_BYTES=64) ;;
  tsan) dir=build-tsan
        flags=(-DNUPMPC_SANITIZE=thread -DNUPMPC_FIXED_SIZE_KERNELS=OFF) ;;
  *) echo "deploy/sanitizer-tree.sh: unknown tree '$kind' (asan|tsan)" >&2; exit 2 ;;
esac
cmake -S . -B "$dir" "${common[@]}" "${flags[@]}" >/dev/null
