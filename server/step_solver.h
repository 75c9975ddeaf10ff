#ifndef NUPMPC_SERVER_STEP_SOLVER_H_
#define NUPMPC_SERVER_STEP_SOLVER_H_

#include <atomic>
#include <optional>

#include "absl/status/status.h"
#include "core/gp/hyperparameter_fit.h"
#include "server/gp_model_cache.h"
#include "server/session_registry.h"
#include "server/spec_conversion.h"

namespace nupmpc::server {

// What the RPC adds to a solve: the time left until its deadline (becomes a time limit)
// and a cancel flag raised when the client goes away.
struct CallContext {
  std::optional<Clock::time_point> deadline;
  const std::atomic<bool>* cancel = nullptr;
};

// One control period on a session: validates and applies the step to a copy of the
// session's problem (the session is untouched if anything is rejected), moves the warm
// start, solves, and fills `out`. Holds the session's lock for the duration.
absl::Status SolveStep(SessionEntry& entry, const v1::Step& step, const CallContext& call, v1::SolveResult* out);

// Stateless: builds a session for the spec, solves cold once, fills `out`. With a budget,
// the session's estimated memory is reserved in it for the duration.
absl::Status SolveOnce(const v1::ProblemSpec& spec, const SizeLimits& limits, const CallContext& call,
                       v1::SolveResult* out, GpModelCache* gp_models = nullptr, MemoryBudget* budget = nullptr);

// The limits of a kernel fit made for a call: the time to its deadline and its cancel flag
// (DEADLINE_EXCEEDED when the deadline already passed). No call: no limits.
absl::StatusOr<gp::FitOptions> FitLimits(const CallContext* call);

// Converts a spec and builds its core session (shared by CreateSession, SolveOnce and
// streams that carry a spec).
struct BuiltSession {
  std::unique_ptr<core::MpcSession> solver;  ///< a core::Session, or a KeepOutSession
  InputTransform transform;
  double default_time_limit_ms = 0.0;
  SessionMemory memory;  ///< its share of the budget (empty without one)
};
// Admission first: the spec's cost (server/session_cost.h) is checked against the
// per-session limits and, with a budget, reserved in it before anything is converted or
// allocated. GP specs take their factorised model from `gp_models` when given (shared
// between sessions); a kernel fit or factorisation on creation stops at `call`'s deadline
// or cancellation.
absl::StatusOr<BuiltSession> BuildSession(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                          GpModelCache* gp_models = nullptr, const CallContext* call = nullptr,
                                          MemoryBudget* budget = nullptr);

// CreateSession and a Control stream's spec: BuildSession, then registers the session
// unless the call's deadline passed or its client cancelled meanwhile (nobody could reach
// a session registered then).
absl::StatusOr<std::shared_ptr<SessionEntry>> CreateAndRegister(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                                                GpModelCache* gp_models, MemoryBudget* budget,
                                                                SessionRegistry* registry, const CallContext& call,
                                                                bool owned_by_stream);

// DEADLINE_EXCEEDED / CANCELLED when the call's deadline passed or its client went away
// (`what` names the work that finished too late, e.g. "the session was built").
absl::Status CheckCallStillWanted(const CallContext& call, const char* what);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_STEP_SOLVER_H_
