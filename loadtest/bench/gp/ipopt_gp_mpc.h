#ifndef NUPMPC_LOADTEST_BENCH_GP_IPOPT_GP_MPC_H_
#define NUPMPC_LOADTEST_BENCH_GP_IPOPT_GP_MPC_H_

// The peer for linGP-SCP: the full GP-MPC NLP ([Nghiem] (21)) solved by Ipopt (Debian's
// coinor-libipopt, MUMPS, limited-memory Hessian). Single shooting: the variables are the
// H inputs; ȳ and σ come from the exact GP by zero-variance simulation with analytic first
// derivatives (forward sensitivities through the NARX recursion, GP gradients from the
// same batched linGP the SCP uses). Rate limits are linear constraints, the chance and
// terminal constraints hard nonlinear ones (the SCP's exact penalty reaches the same plan
// when it is feasible).

#include <memory>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"
#include "core/gp/lingp_scp.h"

namespace nupmpc::bench {

struct IpoptGpMpcOptions {
  double tolerance = 1e-8;  ///< Ipopt's tol (scaled KKT error)
  int max_iterations = 500;
};

struct IpoptGpMpcResult {
  Eigen::VectorXd inputs;
  double objective = 0.0;
  int iterations = 0;
  bool solved = false;  ///< Ipopt returned Solve_Succeeded or Solved_To_Acceptable_Level
  int status = 0;       ///< Ipopt's ApplicationReturnStatus
  double seconds = 0.0;
};

class IpoptGpMpc {
 public:
  static absl::StatusOr<std::unique_ptr<IpoptGpMpc>> Create(const gp::GpModel* model, gp::GpMpcProblem problem,
                                                            IpoptGpMpcOptions options = {});
  ~IpoptGpMpc();
  // Same arguments as LinGpScp::Solve; starts from `initial_inputs` (H values).
  absl::StatusOr<IpoptGpMpcResult> Solve(const Eigen::VectorXd& past_outputs, const Eigen::VectorXd& past_inputs,
                                         const Eigen::VectorXd& reference, const Eigen::VectorXd& initial_inputs);

 private:
  struct Impl;
  explicit IpoptGpMpc(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_GP_IPOPT_GP_MPC_H_
