#ifndef NUPMPC_CORE_SOLUTION_H_
#define NUPMPC_CORE_SOLUTION_H_

#include <optional>
#include <string>

#include "Eigen/Core"
#include "core/options.h"

namespace nupmpc::core {

// How a solve ended. A call error (bad input) is an absl::Status instead.
enum class SolveStatus {
  kConverged,       ///< objective and violation tests met (or the polish verified optimality)
  kIterationLimit,  ///< iteration cap reached; the last finite iterate is returned
  kTimeLimit,       ///< wall-time limit reached
  kNumericalError,  ///< a non-finite number appeared; the last finite iterate is returned
  kCancelled,       ///< the cancel flag was raised
  // The hard bounds cannot all be met. With SolverOptions.elastic_slope the plan minimises
  // J + slope·(distance outside the output bounds) within the input bounds; without it the
  // loop's multipliers showed an empty constraint set (core/session/infeasibility.h) and
  // the plan is its iterate closest to the bounds. max_violation says by how much.
  kInfeasible,
};
const char* SolveStatusName(SolveStatus status);

// Whether a solve must stop now: kCancelled when the limits' flag is raised, kTimeLimit
// when `elapsed_seconds` reached their time limit, else nothing. (Session polls the same
// rule inside its passes too: core/algorithms/interrupt.h.)
std::optional<SolveStatus> LimitReached(const SolveLimits& limits, double elapsed_seconds);

struct SolveSummary {
  SolveStatus status = SolveStatus::kNumericalError;
  Algorithm algorithm = Algorithm::kAuto;  ///< the algorithm that ran (never kAuto)
  int iterations = 0;                      ///< message-passing passes, polish passes included
  double objective = 0.0;                  ///< J of the returned plan (benchmark convention)
  double max_violation = 0.0;              ///< largest distance of a hard-constrained scalar to its set
  bool polished = false;                   ///< the result was verified by the active-set polish
  // Binary inputs: the plan is made discrete after the iterations (nup-algorithms.md §7.2;
  // SolverOptions.discrete_*), and the objective and violation are those of the discrete plan.
  bool rounded = false;       ///< some input was binary and the plan was made discrete
  double discrete_gap = 0.0;  ///< largest distance of a binary (or an M-level sum) to its nearer level when rounded
  int discrete_moves = 0;     ///< level changes the discrete local search accepted after rounding
  bool warm_started = false;
  bool elastic = false;  ///< the elastic fallback ran (SolverOptions.elastic_slope)
  double solve_seconds = 0.0;
  // Nonlinear problems solved by sequential linearisation (KeepOutSession): how many
  // linearised problems were solved (iterations counts the passes over all of them) and
  // the plan's nonlinear violation (deepest intrusion into a keep-out region). 0 for
  // linear problems.
  int linearisations = 0;
  double nonlinear_violation = 0.0;

  // Whether the Solution holds a plan computed by this solve for the problem's current
  // x[0] (u[0] may be applied; the status says how far the solve got). False when the
  // solve was cancelled, or stopped by its time limit or a numerical breakdown before its
  // first complete pass with a finite iterate (an accepted polish counts): the Solution's
  // matrices are then empty and objective and max_violation NaN. A previous solve's plan
  // is never reported as one (it was computed for another state).
  bool has_plan = false;

  // One line for logs and the CLI. Built on demand so that a solve allocates nothing.
  std::string Describe() const;
};

// The plan. Sizes: inputs N×L (row n = u[n]), states (N+1)×M, outputs (N+1)×K.
struct Solution {
  Eigen::MatrixXd inputs;
  Eigen::MatrixXd states;
  Eigen::MatrixXd outputs;
  // Predictive standard deviations of the outputs, (N+1)×K, where the model has them
  // (GP sessions); empty for the linear models, whose predictions are exact.
  Eigen::MatrixXd output_stddev;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SOLUTION_H_
