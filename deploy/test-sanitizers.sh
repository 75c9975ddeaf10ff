#!/usr/bin/env bash
# The sanitizer stages, run by deploy/test.sh (so by CI) after the main suite; any finding
# fails the run. Trees from deploy/sanitizer-tree.sh.
#   1. AddressSanitizer + UBSan (build-asan/): the core and server suites. Not here:
#      no_allocation_test (it replaces malloc, as ASan does), the paper examples and the
#      linGP-vs-Ipopt comparison (minutes under ASan; the same core code runs in the core
#      suites), EveryInstanceThroughSolveOnce... (the long-horizon instances: 90 s under ASan;
#      its code paths run in the other service tests) and IdleSessionsGrow... (ASan's
#      quarantine keeps freed memory, so RSS cannot fall as the test requires).
#   2. Fuzzing: every target of tests/fuzz/ for NUPMPC_FUZZ_SECONDS (default 60) each, from the
#      same tree (deploy/fuzz.sh).
#   3. ThreadSanitizer (build-tsan/): the worker pool, the session strands, the Control
#      stream, the service's unary and streaming calls, SolveFleet and steps solved on
#      gRPC's threads (solve_placement_test), and the client's Session with a control period
#      (client_control_period_test); reports triaged by
#      tests/build/tsan_triage.py (only races inside gRPC's and protobuf's own code are
#      dismissed, each rule with its reason).
# Compiled with clang at -O1, -UNDEBUG (Eigen's assertions on), warnings as errors. Each
# stage first checks that sanitizer stacks are symbolized (deploy/sanitizer-symbolizer.sh).
#   deploy/test-sanitizers.sh [asan|fuzz|tsan]...   (default: all three)
# deploy/test.sh runs the stages one by one; given several, this script runs each even when
# an earlier one failed and exits 1 if any did.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install-deps.sh
source deploy/sanitizer-symbolizer.sh
jobs=$(nproc)

asan_stage() {
  echo "== sanitizer stage 1: AddressSanitizer + UndefinedBehaviorSanitizer (build-asan/)"
  check_symbolizer address
  deploy/sanitizer-tree.sh asan
  core_tests=(message_passing_test scalar_rules_test nonconvex_priors_test discrete_plan_test input_differences_test
              multilevel_inputs_test keep_out_test keep_out_session_test gp_model_test nonlinear_model_test
              benchmark_reference_test session_test elastic_test infeasibility_test step_update_test
              model_update_test interior_point_test)
  # The server's suites; the client library's own tests (reconnection, routing, spec updates,
  # restarts, the load generator) run in the main suite only: the server code they drive
  # runs here through the service tests.
  server_tests=(service_solve_test service_validation_test service_transform_test service_keep_out_test
                service_gp_test service_fleet_test solve_placement_test control_stream_lifetime_test
                worker_pool_test session_strand_test read_timing_test server_binary_test service_admission_test
                service_stream_bounds_test service_malformed_bytes_test memory_budget_test auth_test
                log_format_test hostile_numbers_test hostile_spec_rules_test hostile_sessions_test
                hostile_control_protocol_test hostile_transport_test hostile_solves_test service_model_update_test
                listen_probe_test http_listener_test metrics_port_hostile_test client_control_period_test
                service_deadline_test balancer_auth_test)
  targets=()
  for t in "${core_tests[@]}" "${server_tests[@]}"; do targets+=(--target "$t"); done
  cmake --build build-asan -j "$jobs" "${targets[@]}"
  (
    export ASAN_OPTIONS=detect_leaks=1:detect_stack_use_after_return=1:strict_init_order=1:check_initialization_order=1$sanitizer_options_symbolizer
    export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1$sanitizer_options_symbolizer
    cd build-asan
    # The tests of targets not built above show up as <target>_NOT_BUILT.
    # Labels build (checks of the sources) and deploy (real processes from build/, not these).
    # PythonClient.*, PythonExample.*: the Python client needs the stubs of nupmpc_python (not
    # built here) and is about the client, which the main suite runs against build/'s server.
    ctest --output-on-failure -j "$jobs" --timeout 1200 -LE "build|deploy" \
      -E "_NOT_BUILT$|EveryInstanceThroughSolveOnceAndASessionMatchesTheCore|IdleSessionsGrowTheServersMemoryAndGiveItBack|^Python(Client|Example)\\."
  )

}

fuzz_stage() {
  echo "== sanitizer stage 2: fuzzing (build-asan/, ${NUPMPC_FUZZ_SECONDS:-60} s per target)"
  deploy/fuzz.sh "${NUPMPC_FUZZ_SECONDS:-60}"
}

tsan_stage() {
  echo "== sanitizer stage 3: ThreadSanitizer (build-tsan/)"
  check_symbolizer thread
  deploy/sanitizer-tree.sh tsan
  tsan_tests=(worker_pool_test session_strand_test control_stream_lifetime_test service_stream_bounds_test
              service_solve_test service_fleet_test solve_placement_test http_listener_test
              client_control_period_test)
  targets=()
  for t in "${tsan_tests[@]}"; do targets+=(--target "$t"); done
  cmake --build build-tsan -j "$jobs" "${targets[@]}"
  reports=build-tsan/tsan-reports
  rm -rf "$reports" && mkdir -p "$reports"
  (
    # Reports go to files for the triage; the exit code is the tests' own (exitcode=0).
    # ignore_noninstrumented_modules: malloc, memcpy and the like called from inside the
    # uninstrumented libgrpc and libprotobuf are not checked (TSan cannot see libgrpc's
    # locking around them).
    export TSAN_OPTIONS="log_path=$PWD/$reports/report exitcode=0 halt_on_error=0 ignore_noninstrumented_modules=1 second_deadlock_stack=1 ${sanitizer_options_symbolizer#:}"
    cd build-tsan
    # EveryInstanceThroughSolveOnce...: one call at a time through the long-horizon instances
    # (over a minute under TSan, no concurrency of its own).
    ctest --output-on-failure -j "$jobs" --timeout 1200 -LE "build|deploy" \
      -E "_NOT_BUILT$|EveryInstanceThroughSolveOnceAndASessionMatchesTheCore|^Python(Client|Example)\\."
  )
  /usr/bin/python3 tests/build/tsan_triage.py "$reports"
}

stages=("$@")
[ ${#stages[@]} -eq 0 ] && stages=(asan fuzz tsan)
for stage in "${stages[@]}"; do
  case "$stage" in
    asan|fuzz|tsan) ;;
    *) echo "deploy/test-sanitizers.sh: unknown stage '$stage' (asan|fuzz|tsan)" >&2; exit 2 ;;
  esac
done
if [ ${#stages[@]} -eq 1 ]; then
  "${stages[0]}_stage"
  exit 0
fi
# Several stages: each in a process of its own (set -e does not apply inside a command
# whose failure is tested with ||), every one run whatever the others did.
failed=()
for stage in "${stages[@]}"; do
  "$0" "$stage" || failed+=("$stage")
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "== sanitizer stages FAILED: ${failed[*]}"
  exit 1
fi
