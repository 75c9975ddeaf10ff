#ifndef NUPMPC_SERVER_SESSIONS_STEP_SOLVER_H_
#define NUPMPC_SERVER_SESSIONS_STEP_SOLVER_H_

// A solve on a session (one control period) or on a spec (SolveOnce).

#include "absl/status/status.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/convert/gp_model_cache.h"
#include "server/convert/spec_conversion.h"
#include "server/sessions/call_context.h"
#include "server/sessions/memory_budget.h"
#include "server/sessions/session_registry.h"

namespace nupmpc::server {

// One control period on a session: the Step becomes a core StepUpdate, the session
// applies it (all checked before anything changes: a rejected step leaves the session as
// it was), the warm start moves, the session solves, and the result fills `out`. Runs as
// a task of the session's strand (or where nothing else uses the session).
absl::Status SolveStep(SessionEntry& entry, const v1::Step& step, const CallContext& call, v1::SolveResult* out);

// Stateless: builds a session for the spec, solves cold once, fills `out`. With a budget,
// the session's estimated memory is reserved in it for the duration.
absl::Status SolveOnce(const v1::ProblemSpec& spec, const SizeLimits& limits, const CallContext& call,
                       v1::SolveResult* out, GpModelCache* gp_models = nullptr, MemoryBudget* budget = nullptr);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_STEP_SOLVER_H_
