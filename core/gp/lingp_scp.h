#ifndef NUPMPC_CORE_GP_LINGP_SCP_H_
#define NUPMPC_CORE_GP_LINGP_SCP_H_

// GP-MPC by linGP sequential convex programming ([Nghiem] Algorithm 1) with the convex
// subproblems solved by the NUP core. The GP-MPC problem ([Nghiem] (21)), single input
// and output, NARX layout (core/gp/narx.h), horizon H, k = t..t+H-1:
//
//   min  Σ Q (ȳ[k] - r[k])² + R (u[k] - u[k-1])²  +  λ Σ (chance-constraint violations)
//   s.t. ȳ[k] = μ(x[k]),  σ²[k] = σ²(x[k])   (zero-variance multi-step GP prediction)
//        u_min ≤ u[k] ≤ u_max,  Δu_min ≤ u[k] - u[k-1] ≤ Δu_max              (hard)
//        ȳ[k] + κ σ[k] ≤ y_max,  ȳ[k] - κ σ[k] ≥ y_min                       (exact penalty λ)
//        |ȳ[t+H-1] - r ± κ σ[t+H-1]| ≤ δ (terminal, optional)                 (exact penalty λ)
//
// Each SCP iteration linearises the GP around the nominal plan with the linGP (one batched
// solve over the horizon), which makes the model an LTV system: the NUP state is
// [ȳ[k], ..., ȳ[k-l], u[k], ..., u[k-m]], the NUP input is Δu[k] (box + Gaussian part
// R: the rate limit and the move cost), outputs carry the tracking cost, the trust-region
// boxes |ȳ - ȳ*| ≤ ρ and |u - u*| ≤ ρ (hard, intersected with the input box) and the two
// chance-constraint rows. The subproblem runs on IFFBDD, warm from the previous one.
//
// Variance terms: σ[k] = sqrt(ξᵀ V̂ ξ) (ξ = [1; Δx]) is convex in the plan, so the chance
// constraints are second-order cones; the NUP core takes linear constraints only. Each
// SCP iteration replaces σ[k] by its first-order expansion at the nominal plan,
// σ* + (V̂ ξ₀ / σ*)ᵀ Δx — a documented convex approximation that is exact at the nominal
// plan, so at convergence (the plan is its own nominal) the constraints hold with the
// exact GP variance. Acceptance uses the exact GP (mean and variance) as in [Nghiem]
// (17): a step is taken only if the exact merit improves enough. Summary.max_violation
// reports the final plan's constraints under the exact GP.

#include <memory>
#include <string>
#include <string_view>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"
#include "core/gp/narx.h"
#include "core/session/session.h"
#include "core/snapshot/state_archive.h"

namespace nupmpc::gp {

struct GpMpcProblem {
  NarxLayout layout;
  int horizon = 12;                  ///< H
  double output_weight = 10.0;       ///< Q
  double input_change_weight = 0.1;  ///< R
  double input_min = -1.0, input_max = 1.0;
  double rate_min = -0.5, rate_max = 0.5;
  double output_min = -1.2, output_max = 1.2;  ///< on ȳ ∓ κσ; -∞ / +∞: no constraint on that side
  double sigma_multiple = 2.0;                 ///< κ
  double terminal_tolerance = 0.075;           ///< δ; ≤ 0 or ∞: no terminal constraint
};
absl::Status Validate(const GpMpcProblem& problem);

struct ScpOptions {
  double initial_trust_radius = 0.5;  ///< ρ(0)
  double min_trust_radius = 1e-7;     ///< stop when ρ falls below (no acceptable step left)
  double max_trust_radius = 4.0;
  double r0 = 0.0, r1 = 0.25, r2 = 0.75;  ///< thresholds on actual/predicted reduction
  double beta_fail = 0.5, beta_success = 2.0;
  double tolerance = 1e-9;  ///< ε on the predicted reduction |δ̃|
  int max_iterations = 50;  ///< j_max
  double penalty = 1e3;     ///< λ of the exact penalty
  // Cold starts try u[t-1] and this many evenly spaced levels of the input box held over
  // the horizon, and start from the one with the least exact merit.
  int cold_start_levels = 9;
};
absl::Status Validate(const ScpOptions& options);

struct ScpPlan {
  Eigen::VectorXd inputs;  ///< u[t..t+H-1]
  Eigen::VectorXd means;   ///< ȳ[t..t+H-1] under the exact GP
  Eigen::VectorXd sigmas;  ///< σ[t..t+H-1] under the exact GP
};

struct ScpSummary {
  bool converged = false;
  // How the solve ended in the core's terms: converged, iteration limit (also when the
  // trust region collapsed without an acceptable step), time limit or cancelled.
  core::SolveStatus status = core::SolveStatus::kIterationLimit;
  int iterations = 0;  ///< SCP iterations (subproblems solved)
  int accepted = 0;    ///< of which accepted
  // The returned plan was computed in this solve: some step was accepted or the SCP
  // converged (else it is the warm plan shifted, or the cold start's constant guess).
  bool has_plan = false;
  int inner_passes = 0;        ///< NUP message-passing passes over all subproblems
  double merit = 0.0;          ///< exact-penalty cost ϕ of the returned plan (exact GP)
  double objective = 0.0;      ///< its tracking part J
  double max_violation = 0.0;  ///< largest chance/terminal constraint violation (exact GP)
  double trust_radius = 0.0;
  double inner_seconds = 0.0;  ///< in the NUP solves (subproblem (16) alone)
  double seconds = 0.0;
};

class LinGpScp {
 public:
  // `model` must outlive the solver.
  static absl::StatusOr<std::unique_ptr<LinGpScp>> Create(const GpModel* model, GpMpcProblem problem,
                                                          ScpOptions options = {});

  // One MPC step at time t. past_outputs: y[t-l..t-1] (l values, measured); past_inputs:
  // u[t-m-1..t-1] (m+1 values, applied); reference: r[t..t+H-1] (H values, or 1).
  // Starts from the warm plan if there is one (ShiftWarmStart() between steps), else
  // from the best of a few constant inputs (ScpOptions.cold_start_levels).
  // `limits` (optional): max_iterations caps the SCP iterations (below
  // ScpOptions.max_iterations), the time limit and cancel flag are checked before every
  // SCP iteration and passed on to the inner solves; a stopped solve returns the best plan
  // accepted so far (always one that satisfies the input constraints).
  absl::StatusOr<ScpSummary> Solve(const Eigen::VectorXd& past_outputs, const Eigen::VectorXd& past_inputs,
                                   const Eigen::VectorXd& reference, ScpPlan* plan,
                                   const core::SolveLimits* limits = nullptr);
  void ShiftWarmStart();
  void ResetWarmStart() { has_warm_ = false; }
  // Snapshots (gp_session_state.cc): the warm plan and the subproblem session's state.
  absl::Status SaveState(std::string* out);
  absl::Status RestoreState(std::string_view bytes);

  // ϕ of inputs under the exact GP (for baselines and tests); also fills means/sigmas.
  double ExactMerit(const Eigen::VectorXd& inputs, ScpPlan* evaluated, double* objective, double* max_violation) const;

 private:
  LinGpScp(const GpModel* model, GpMpcProblem problem, ScpOptions options, core::Problem shape);
  // Exact zero-variance simulation of `inputs` from the current past; fills the
  // regressors (H×d), means and the linGP at every regressor (σ from it).
  void Simulate(const Eigen::VectorXd& inputs, Eigen::MatrixXd* regressors, Eigen::VectorXd* means,
                std::vector<LinGp>* lin) const;
  double Merit(const Eigen::VectorXd& inputs, const Eigen::VectorXd& means, const Eigen::VectorXd& sigmas,
               double* objective, double* max_violation) const;
  // Writes the linearised subproblem around the nominal plan into problem_.
  void BuildSubproblem(double trust_radius);
  // Clips to the input box and the rate limits from u[t-1], in order.
  void ProjectToInputConstraints(Eigen::VectorXd* inputs) const;
  double UpperBound(int k) const;
  double LowerBound(int k) const;
  // Snapshots: both directions; `inner` holds the subproblem session's bytes.
  void PersistState(core::StateArchive& archive, std::string& inner);

  const GpModel* model_;
  GpMpcProblem p_;
  ScpOptions options_;
  core::Problem problem_;
  std::unique_ptr<core::Session> session_;
  core::Solution solution_;
  // The current step's data.
  Eigen::VectorXd past_outputs_, past_inputs_, reference_;
  // Nominal plan and its exact evaluation; candidate likewise.
  Eigen::VectorXd nominal_u_, nominal_y_, candidate_u_, candidate_y_;
  Eigen::MatrixXd nominal_x_, candidate_x_;
  std::vector<LinGp> nominal_lin_, candidate_lin_;
  mutable LinearisationScratch scratch_;  // Simulate() is const; the scratch is per solver
  bool has_warm_ = false;
};

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_LINGP_SCP_H_
