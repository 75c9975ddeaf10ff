#ifndef NUPMPC_CORE_NUPMPC_H_
#define NUPMPC_CORE_NUPMPC_H_

// The core's public facade for embedding it in a program: everything needed to describe a
// problem (Problem, ScalarPrior, InputMap), choose options (SolverOptions, SolveLimits),
// create a session, step it (StepUpdate) and solve it (MpcSession, Solution, SolveSummary). The algorithms behind a
// session (core/algorithms/) and its internals (core/session/session.h) stay out of
// sight: code that includes only this header depends on nothing but this interface.
//
//   NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<MpcSession> session, CreateSession(problem));
//   session->SetInitialState(x0);
//   Solution plan;
//   absl::StatusOr<SolveSummary> summary = session->Solve(SolveLimits{}, &plan);

#include <memory>

#include "absl/status/statusor.h"
#include "core/options.h"
#include "core/priors/scalar_prior.h"
#include "core/problem.h"
#include "core/session/input_mapped_session.h"
#include "core/session/mpc_session.h"
#include "core/session/step_update.h"
#include "core/solution.h"

namespace nupmpc::core {

// A session for a linear problem: validates `problem` and `options` (INVALID_ARGUMENT or
// FAILED_PRECONDITION naming the field), picks the algorithm (SolverOptions.algorithm) and
// allocates everything the solves need.
absl::StatusOr<std::unique_ptr<MpcSession>> CreateSession(Problem problem, SolverOptions options = {});

// The same for a problem whose inputs are multi-level or carry priors on their differences
// (`map`): the session solves MapInputs(problem, map) and the caller states, updates
// (MpcSession::Apply) and reads its own inputs, outputs and states.
absl::StatusOr<std::unique_ptr<MpcSession>> CreateSession(Problem problem, InputMap map, SolverOptions options = {});

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_NUPMPC_H_
