#ifndef NUPMPC_SERVER_STEP_SOLVER_H_
#define NUPMPC_SERVER_STEP_SOLVER_H_

// A solve on a session (one control period) or on a spec (SolveOnce).

#include "absl/status/status.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/call_context.h"
#include "server/gp_model_cache.h"
#include "server/memory_budget.h"
#include "server/session_registry.h"
#include "server/spec_conversion.h"

namespace nupmpc::server {

// One control period on a session: the Step becomes a core StepUpdate, the session
// applies it (all checked before anything changes: a rejected step leaves the session as
// it was), the warm start moves, the session solves, and the result fills `out`. Runs as
// a task of the session's strand (or where nothing else uses the session).
absl::Status SolveStep(SessionEntry& entry, const v1::Step& step, const CallContext& call, v1::SolveResult* out);

// Whether a session's next solve reads its thread's CPU time (for last_solve_cpu_ms). That
// takes two system calls per solve (the thread CPU clock has no vDSO path), a cost on the
// round trip of the shortest solves. A solve's wall time bounds its CPU time, so after a
// solve known to be short (wall time under kWallTimeBoundsCpuTimeMs) the next one records
// its wall time as its CPU time: if that one took longer (or was preempted), its session's
// next step may go to a worker once, and that solve is measured again.
inline constexpr double kWallTimeBoundsCpuTimeMs = 0.2;
bool MeasuresSolveCpuTime(double last_solve_ms);

// Stateless: builds a session for the spec, solves cold once, fills `out`. With a budget,
// the session's estimated memory is reserved in it for the duration.
absl::Status SolveOnce(const v1::ProblemSpec& spec, const SizeLimits& limits, const CallContext& call,
                       v1::SolveResult* out, GpModelCache* gp_models = nullptr, MemoryBudget* budget = nullptr);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_STEP_SOLVER_H_
