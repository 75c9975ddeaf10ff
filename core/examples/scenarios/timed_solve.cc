#include "core/examples/scenarios/timed_solve.h"

#include <chrono>
#include <memory>

#include "core/public/session.h"
#include "core/public/status_macros.h"

namespace nupmpc::examples {

absl::StatusOr<TimedPlan> SolveWithBudget(const core::Problem& problem, int max_iterations,
                                          core::SolverOptions options) {
  options.max_iterations = max_iterations;
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<core::Session> session, core::Session::Create(problem, options));
  TimedPlan result;
  const auto start = std::chrono::steady_clock::now();
  NUPMPC_ASSIGN_OR_RETURN(result.summary, session->Solve(&result.plan));
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace nupmpc::examples
