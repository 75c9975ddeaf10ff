#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_TIMED_SOLVE_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_TIMED_SOLVE_H_

// One cold solve of a whole example problem with an iteration budget, timed (the
// examples with non-convex priors run a fixed budget, nup-algorithms.md §7.2).

#include "absl/status/statusor.h"
#include "core/nupmpc.h"

namespace nupmpc::examples {

struct TimedPlan {
  core::Solution plan;
  core::SolveSummary summary;
  double seconds = 0.0;  ///< the solve alone (not the session's set-up)
};

// `options.max_iterations` is set to `max_iterations`; everything else is as given.
absl::StatusOr<TimedPlan> SolveWithBudget(const core::Problem& problem, int max_iterations,
                                          core::SolverOptions options = {});

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_TIMED_SOLVE_H_
