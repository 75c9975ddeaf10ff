#ifndef NUPMPC_CORE_GP_GP_MPC_SESSION_H_
#define NUPMPC_CORE_GP_GP_MPC_SESSION_H_

// A receding-horizon GP-MPC session behind the same interface as the linear sessions
// (core::MpcSession), so that the service holds, steps, shifts and limits it like any
// other: it owns the factorised GP model (Cholesky factor, pivoted low-rank factor and its
// basis, computed once, at creation) and a linGP-SCP solver on it, and each Solve() only
// re-runs the SCP.
//
// The session in the MpcSession's terms (N = H, one input, one output):
// * state x[0] = the NARX past window [y[t-l..t-1], u[t-m-1..t-1]] (l + m + 1 values,
//   oldest first): the measured outputs and the applied inputs;
// * inputs u[n] = u[t+n], n = 0..H-1;
// * outputs y[0] = y[t-1] (measured), y[n+1] = ȳ[t+n] (zero-variance GP prediction, whose
//   regressor includes u[t+n]); output_stddev the latent σ of each (0 for the measured one);
// * states x[n] = the past window at t+n along the plan.
// problem() describes the costs in core terms (inputs Box(u_min, u_max), outputs at steps
// 1..H Gaussian with mean r[t+n-1] and weight 2Q); its model matrices are zero, because the
// GP is the model. Apply() takes a new state (the window) and reference, nothing else.

#include <memory>
#include <string>
#include <string_view>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"
#include "core/gp/lingp_scp.h"
#include "core/session/mpc_session.h"

namespace nupmpc::gp {

class GpMpcSession final : public core::MpcSession {
 public:
  // `model` may be shared with other sessions (it is immutable). `reference`: r[t..t+H-1]
  // (H values, or 1 for a constant one). INVALID_ARGUMENT naming the field for a bad
  // problem, options or reference.
  static absl::StatusOr<std::unique_ptr<GpMpcSession>> Create(std::shared_ptr<const GpModel> model,
                                                              GpMpcProblem problem, ScpOptions options,
                                                              const Eigen::VectorXd& reference);

  const core::Problem& problem() const override { return shape_; }
  // The subproblems run on IFFBDD.
  core::Algorithm algorithm() const override { return core::Algorithm::kIffbdd; }
  absl::Status SetInitialState(const Eigen::VectorXd& window) override;
  absl::Status Apply(const core::StepUpdate& update) override;
  void ShiftWarmStart() override { scp_->ShiftWarmStart(); }
  // Nothing to give back: the factorised GP is the model, not scratch (and may be shared),
  // and the SCP's per-step buffers are a few horizons long.
  void ReleaseWorkspace() override {}
  // SolveSummary in GP terms: iterations = NUP passes over all subproblems,
  // linearisations = SCP iterations, objective = the tracking cost J of (21) (without the
  // exact penalty), max_violation = the largest chance/terminal-constraint violation under
  // the exact GP. limits.max_iterations caps the SCP iterations.
  absl::StatusOr<core::SolveSummary> Solve(const core::SolveLimits& limits, core::Solution* solution) override;

  // The past window and the reference (restored through Apply()), whether a solve ran,
  // and the SCP's warm state (gp_session_state.cc). The model is the creation spec's.
  absl::Status SaveState(std::string* out) override;
  absl::Status RestoreState(std::string_view bytes) override;

  const GpModel& model() const { return *model_; }
  const GpMpcProblem& gp_problem() const { return problem_; }

 private:
  GpMpcSession(std::shared_ptr<const GpModel> model, GpMpcProblem problem);
  // The reference r[t..t+H-1] as problem() states it.
  void ReadReference(Eigen::VectorXd* reference) const;
  void FillSolution(const ScpPlan& plan, core::Solution* solution) const;
  // Snapshots: both directions; `scp` holds the SCP's bytes, `window` and `reference` the
  // values Apply() takes.
  void PersistState(core::StateArchive& archive, std::string& scp, Eigen::VectorXd& window, Eigen::VectorXd& reference);

  std::shared_ptr<const GpModel> model_;  // the SCP keeps a pointer to it
  GpMpcProblem problem_;
  core::Problem shape_;
  std::unique_ptr<LinGpScp> scp_;
  // shape_'s initial mean and output means in the form LinGpScp::Solve takes, kept so that a
  // solve copies nothing; written together with shape_ (SetInitialState, Apply).
  Eigen::VectorXd past_outputs_, past_inputs_, reference_;
  ScpPlan plan_;
  bool solved_ = false;  ///< a Solve() has run since creation (the carried plan is warm)
};

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_GP_MPC_SESSION_H_
