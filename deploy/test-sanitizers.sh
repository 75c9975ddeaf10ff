#!/usr/bin/env bash
# The sanitizer suite, run by deploy/test.sh (so by CI) after the main suite: an
# AddressSanitizer + UndefinedBehaviorSanitizer build in build-asan/ running the core and
# server tests; any finding fails the run.
#   * Compiled for x86-64-v3 with Eigen's alignment raised to 64 bytes (what AVX-512 builds
#     use): the aligned-allocation path on which AVX-512 servers crashed (issue 17) runs
#     under ASan whatever CPU the tests run on.
#   * -O1 with Eigen's assertions on; compiler warnings are errors.
#   * UBSan without the checks that double its compile time (see CMakeLists.txt).
#   * Not here: no_allocation_test (it replaces malloc, as ASan does), the paper examples and
#     the linGP-vs-Ipopt comparison (minutes under ASan; the same core code runs in the
#     core suites), EveryInstanceThroughSolveOnce... (the long-horizon instances: 90 s under
#     ASan; its code paths run in the other service tests) and IdleSessionsGrow... (ASan's
#     quarantine keeps freed memory, so RSS cannot fall as the test requires).
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install-deps.sh
echo "== sanitizer suite: AddressSanitizer + UndefinedBehaviorSanitizer (build-asan/)"
if [ ! -f build-asan/CMakeCache.txt ]; then
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
    -DNUPMPC_SANITIZE=address,undefined \
    -DNUPMPC_CPU_BASELINE=x86-64-v3 -DNUPMPC_WERROR=ON -DCMAKE_CXX_FLAGS=-DEIGEN_MAX_ALIGN_BYTES=64 >/dev/null
fi
core_tests=(message_passing_test scalar_rules_test nonconvex_priors_test discrete_plan_test input_differences_test
            multilevel_inputs_test keep_out_test keep_out_session_test gp_model_test nonlinear_model_test
            benchmark_reference_test session_test elastic_test infeasibility_test step_update_test)
server_tests=(service_solve_test service_validation_test service_transform_test service_keep_out_test
              service_gp_test control_stream_lifetime_test worker_pool_test session_strand_test loadtest_test
              server_binary_test service_admission_test service_stream_bounds_test service_malformed_bytes_test
              memory_budget_test client_reconnect_test closed_loop_restart_test reconnect_fidelity_test
              client_spec_update_test session_routing_test auth_test log_format_test hostile_numbers_test
              hostile_solves_test)
targets=()
for t in "${core_tests[@]}" "${server_tests[@]}"; do targets+=(--target "$t"); done
cmake --build build-asan -j "$(nproc)" "${targets[@]}"
export ASAN_OPTIONS=detect_leaks=1:detect_stack_use_after_return=1:strict_init_order=1:check_initialization_order=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
cd build-asan
# The tests of targets not built above show up as <target>_NOT_BUILT.
# Labels build (checks of the sources) and deploy (real processes from build/, not these).
# PythonClient.*, PythonExample.*: the Python client needs the stubs of nupmpc_python (not built
# here) and is about the client, which the main suite runs against build/'s server.
ctest --output-on-failure -j "$(nproc)" --timeout 1200 -LE "build|deploy" \
  -E "_NOT_BUILT$|EveryInstanceThroughSolveOnceAndASessionMatchesTheCore|IdleSessionsGrowTheServersMemoryAndGiveItBack|^Python(Client|Example)\\."
