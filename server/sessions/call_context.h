#ifndef NUPMPC_SERVER_SESSIONS_CALL_CONTEXT_H_
#define NUPMPC_SERVER_SESSIONS_CALL_CONTEXT_H_

// What an RPC adds to the work done for it: the time left until its deadline and a cancel
// flag raised when its client goes away, and how they become the limits of a solve or a fit.

#include <atomic>
#include <chrono>
#include <optional>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/gp/hyperparameter_fit.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

using Clock = std::chrono::steady_clock;

struct CallContext {
  std::optional<Clock::time_point> deadline;  ///< the RPC's (gRPC deadline): after it nobody listens
  const std::atomic<bool>* cancel = nullptr;
  // A step's: when the server received it, from which its answer's deadline is counted
  // (Step.budget_ms, Timing.period_ms), and what sending the answer is expected to take.
  std::optional<Clock::time_point> received_at = std::nullopt;
  double send_cost_ms = 0.0;
};

// A solve's limits from the session's time limit (`session_limit_ms`, 0: none), the step's
// (time_limit_ms, max_iterations; may be null) and the call's deadline and cancel flag.
// DEADLINE_EXCEEDED when the deadline already passed.
absl::StatusOr<core::SolveLimits> SolveLimitsFor(double session_limit_ms, const v1::Step* step,
                                                 const CallContext& call);

// The limits of a kernel fit made for a call: the time to its deadline and its cancel flag
// (DEADLINE_EXCEEDED when the deadline already passed). No call: no limits.
absl::StatusOr<gp::FitOptions> FitLimits(const CallContext* call);

// DEADLINE_EXCEEDED / CANCELLED when the call's deadline passed or its client went away
// (`what` names the work that finished too late, e.g. "the session was built").
absl::Status CheckCallStillWanted(const CallContext& call, const char* what);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_CALL_CONTEXT_H_
