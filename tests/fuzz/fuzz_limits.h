#ifndef NUPMPC_FUZZ_FUZZ_LIMITS_H_
#define NUPMPC_FUZZ_FUZZ_LIMITS_H_

// What the fuzz targets let one input cost: the server's own admission rules with limits
// small enough that every input is a few milliseconds of work (the server refuses larger
// sizes before it allocates, which is one of the properties under test), and the checks
// every answer must pass.

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "nupmpc/v1/nupmpc.pb.h"
#include "server/convert/spec_conversion.h"

namespace nupmpc::fuzz {

inline server::SizeLimits SmallLimits() {
  server::SizeLimits l;
  l.max_states = 16;
  l.max_inputs = 8;
  l.max_outputs = 16;
  l.max_horizon = 64;
  l.max_scalars = 100'000;
  l.max_iterations = 50;
  l.max_gp_points = 64;
  l.max_input_levels = 8;
  l.max_keep_out_regions = 4;
  l.max_session_bytes = 64LL << 20;
  l.max_pass_flops = 1e7;
  return l;
}

// A property violated: libFuzzer keeps the input as a crash.
[[noreturn]] inline void Violated(const char* what) {
  std::fprintf(stderr, "fuzz property violated: %s\n", what);
  std::abort();
}

// No NaN or infinity leaves the server in a result; a result without a plan carries none.
inline void CheckResult(const v1::SolveResult& r) {
  if (!r.has_plan()) {
    if (r.inputs_size() + r.states_size() + r.outputs_size() > 0) Violated("plan fields without has_plan");
    return;
  }
  for (double v : r.inputs()) {
    if (!std::isfinite(v)) Violated("non-finite input in a plan");
  }
  for (double v : r.states()) {
    if (!std::isfinite(v)) Violated("non-finite state in a plan");
  }
  for (double v : r.outputs()) {
    if (!std::isfinite(v)) Violated("non-finite output in a plan");
  }
}

}  // namespace nupmpc::fuzz

#endif  // NUPMPC_FUZZ_FUZZ_LIMITS_H_
