#!/usr/bin/env bash
# The layering check must see what it is there to see: on a copy of the sources it passes,
# and each forbidden include planted in the copy (one at a time) makes it fail, naming
# the file and the rule; so does a CMakeLists.txt that exports the repository root.
#   layering_check_selftest.sh SOURCE_DIR
set -euo pipefail
src=$1
check="$(dirname "$0")/layering_check.py"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for room in CMakeLists.txt cmake cli core proto server client loadtest tests; do
  cp -r "$src/$room" "$work/"
done
python3 "$check" "$work"

# plant FILE LINE: appends LINE to FILE, expects the check to fail, restores FILE.
plant() {
  local file=$1 line=$2
  cp "$work/$file" "$work/planted.orig"
  printf '%s\n' "$line" >>"$work/$file"
  echo "-- planted in $file: $line"
  if python3 "$check" "$work"; then
    echo "FAIL: the check passed with a forbidden include planted in $file" >&2
    exit 1
  fi
  mv "$work/planted.orig" "$work/$file"
}
plant client/client.h '#include "core/problem.h"'
plant client/problem_file.cc '#include "server/convert/spec_conversion.h"'
plant client/cli_main.cc '#include "loadtest/instances/benchmark_instance.h"'
plant core/session/session.cc '#include "core/gp/gp_model.h"'
plant core/problem.h '#include "core/examples/scenarios/dac.h"'
plant core/problem.cc '#include "server/convert/spec_conversion.h"'
plant core/options.cc '#include "nupmpc/v1/nupmpc.pb.h"'
plant core/gp/gp_model.cc '#include "server/convert/gp_conversion.h"'
plant server/sessions/step_solver.cc '#include "loadtest/core_baseline.h"'
plant server/rpc/mpc_service.cc '#include "client/client.h"'
# The server's folders: conversion below sessions and without gRPC, sessions below the RPCs.
plant server/convert/spec_conversion.cc '#include "server/sessions/session_registry.h"'
plant server/convert/result_conversion.cc '#include "grpcpp/grpcpp.h"'
plant server/sessions/step_solver.cc '#include "server/rpc/control_stream.h"'
plant server/scheduling/worker_pool.cc '#include "server/state/server_state.h"'
plant server/auth/token_file.cc '#include "server/sessions/session_registry.h"'
plant server/rpc/control_stream.cc '#include "server/grpc_server.h"'
plant loadtest/instances/benchmark_instance.cc '#include "server/sessions/step_solver.h"'
plant loadtest/load_level.cc '#include "loadtest/bench/bench_report.h"'
plant core/model/factor_graph.cc '#include "../../server/spec_conversion.h"'
plant core/problem.cc '#include "gp/gp_model.h"'
# Outside core/, the core only through its public headers (core/nupmpc.h, core/public/).
plant server/sessions/session_factory.cc '#include "core/session/session.h"'
plant loadtest/core_baseline.cc '#include "core/algorithms/iffbdd.h"'
plant core/examples/scenarios/dac.cc '#include "core/session/footprint.h"'
plant tests/fuzz/step_fuzzer.cc '#include "core/util/status_macros.h"'
# The standalone public headers: the C++ standard library only; the client sees no other.
plant core/public/standalone/step_control.h '#include "absl/strings/str_cat.h"'
plant core/public/standalone/step_control.h '#include "core/problem.h"'
plant core/public/standalone/step_control.h '#include <Eigen/Core>'
plant client/nonlinear_session.cc '#include "core/public/session.h"'
plant client/nonlinear_session.cc '#include "core/nupmpc.h"'
plant client/CMakeLists.txt 'target_include_directories(nupmpc_client PUBLIC ${PROJECT_SOURCE_DIR})'
python3 "$check" "$work"
echo "ok: the check fails on every planted forbidden include and passes without them"
