#ifndef NUPMPC_LOADTEST_BENCH_GP_GP_CLOSED_LOOP_H_
#define NUPMPC_LOADTEST_BENCH_GP_GP_CLOSED_LOOP_H_

// The closed loop of [Nghiem] §V, run twice on the tanh plant with the same measurement
// noise: once driven by linGP-SCP (on the NUP core), once by Ipopt on the full NLP. In the
// Ipopt loop a shadow linGP-SCP solves every step's problem too, so the two solvers' plans
// are compared on identical problems.

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"
#include "core/gp/lingp_scp.h"

namespace nupmpc::bench {

struct GpClosedLoopOptions {
  int steps = 100;
  std::uint32_t noise_seed = 7;
  bool with_ipopt = true;
  double ipopt_tolerance = 1e-8;
};

struct ClosedLoopTrace {
  Eigen::VectorXd y, u, reference;    ///< measured output, applied input, reference per step
  std::vector<double> step_seconds;   ///< solver time per MPC step
  std::vector<double> inner_seconds;  ///< linGP-SCP: time in the NUP subproblems
  int unconverged = 0;                ///< steps the solver did not report converged
  double max_violation = 0.0;         ///< largest exact-GP constraint violation of any plan applied
  double tracking_rmse = 0.0;         ///< of y - reference over all steps
};

struct GpComparison {
  ClosedLoopTrace scp, ipopt;
  double max_plan_difference = 0.0;  ///< max over steps of ‖u_scp - u_ipopt‖∞ on the same problem
  double max_objective_gap = 0.0;    ///< max over steps of (J_scp - J_ipopt) / max(1e-9, |J_ipopt|), exact GP
};

absl::StatusOr<GpComparison> RunGpClosedLoops(const gp::GpModel& model, const gp::GpMpcProblem& problem,
                                              const GpClosedLoopOptions& options);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_GP_GP_CLOSED_LOOP_H_
