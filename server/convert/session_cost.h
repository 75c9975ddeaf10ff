#ifndef NUPMPC_SERVER_CONVERT_SESSION_COST_H_
#define NUPMPC_SERVER_CONVERT_SESSION_COST_H_

// Admission by cost: what a spec would cost, computed from its numbers alone before
// anything is converted or allocated, and the per-session limits it must respect. The
// server reserves the memory in its budget (server/sessions/memory_budget.h) before it builds.

#include <cstdint>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/convert/spec_conversion.h"

namespace nupmpc::server {

struct SessionCost {
  std::int64_t build_bytes = 0;      ///< peak while the session is built (a GP kernel fit, factorisation)
  std::int64_t resident_bytes = 0;   ///< kept while the session exists (problem, warm start, GP factors)
  std::int64_t scratch_bytes = 0;    ///< solver scratch, given back while the session is idle
  std::int64_t transient_bytes = 0;  ///< allocated and freed again within one solve
  double pass_flops = 0.0;           ///< one message-passing pass over the horizon
  // What a session holds while it solves (its reservation).
  std::int64_t session_bytes() const { return resident_bytes + scratch_bytes + transient_bytes; }
};

// The cost of a ProblemSpec (linear, multi-level, input-difference, keep-out or GP).
// RESOURCE_EXHAUSTED naming the field and the limit for any count over `limits`
// (dimensions, input_levels[i].count, keep_out.regions, GP points), and for a session
// whose estimated memory or pass work is over max_session_bytes / max_pass_flops.
absl::StatusOr<SessionCost> SpecCost(const v1::ProblemSpec& spec, const SizeLimits& limits);

// The peak memory of a FitGpModel on `model` (its O(P²) matrices); checks the point limit.
absl::StatusOr<std::int64_t> GpFitBytes(const v1::GpModel& model, const std::string& path, const SizeLimits& limits);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_SESSION_COST_H_
