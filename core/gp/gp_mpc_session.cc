#include "core/gp/gp_mpc_session.h"

#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::gp {

GpMpcSession::GpMpcSession(std::shared_ptr<const GpModel> model, GpMpcProblem problem)
    : model_(std::move(model)), problem_(std::move(problem)) {}

absl::StatusOr<std::unique_ptr<GpMpcSession>> GpMpcSession::Create(std::shared_ptr<const GpModel> model,
                                                                   GpMpcProblem problem, ScpOptions options,
                                                                   const Eigen::VectorXd& reference) {
  if (model == nullptr) return absl::InvalidArgumentError("model: must not be null");
  NUPMPC_RETURN_IF_ERROR(Validate(problem));
  const int H = problem.horizon, l = problem.layout.output_lags, m = problem.layout.input_lags;
  if (reference.size() != H && reference.size() != 1) {
    return absl::InvalidArgumentError(absl::StrCat("reference: expected ", H, " values or 1, got ", reference.size()));
  }
  if (!reference.allFinite()) return absl::InvalidArgumentError("reference: contains a non-finite number");
  std::unique_ptr<GpMpcSession> session(new GpMpcSession(std::move(model), std::move(problem)));
  const GpMpcProblem& p = session->problem_;
  NUPMPC_ASSIGN_OR_RETURN(session->scp_, LinGpScp::Create(session->model_.get(), p, options));

  core::Problem& shape = session->shape_;
  shape = core::Problem::TimeInvariant(/*M=*/l + m + 1, /*L=*/1, /*K=*/1, /*N=*/H);
  for (int n = 0; n < H; ++n) shape.mutable_input_prior(n, 0) = core::ScalarPrior::Box(p.input_min, p.input_max);
  for (int n = 1; n <= H; ++n) {
    const double r = reference.size() == H ? reference(n - 1) : reference(0);
    shape.mutable_output_prior(n, 0) = core::ScalarPrior::Gaussian(r, 1.0 / (2.0 * p.output_weight));
  }
  session->past_outputs_.setZero(l);
  session->past_inputs_.setZero(m + 1);
  session->ReadReference(&session->reference_);
  return session;
}

void GpMpcSession::ReadReference(Eigen::VectorXd* reference) const {
  reference->resize(problem_.horizon);
  for (int n = 0; n < problem_.horizon; ++n) (*reference)(n) = shape_.output_prior(n + 1, 0).mean;
}

absl::Status GpMpcSession::SetInitialState(const Eigen::VectorXd& window) {
  NUPMPC_RETURN_IF_ERROR(core::CheckInitialState(shape_, window));
  const int l = problem_.layout.output_lags;
  shape_.initial_mean = window;
  past_outputs_ = window.head(l);
  past_inputs_ = window.tail(window.size() - l);
  return absl::OkStatus();
}

absl::Status GpMpcSession::Apply(const core::StepUpdate& update) {
  if (update.changes_priors()) {
    return absl::FailedPreconditionError(
        "update: a GP session's costs and input box are fixed at creation; it takes a new reference in reference");
  }
  NUPMPC_RETURN_IF_ERROR(core::RefusePreviousInput(update));
  NUPMPC_RETURN_IF_ERROR(core::RefuseModel(update, "GP sessions (the GP is their model)"));
  if (update.state.has_value()) NUPMPC_RETURN_IF_ERROR(core::CheckStepState(shape_.num_states, *update.state));
  if (update.reference.has_value()) {
    const Eigen::VectorXd& r = *update.reference;
    const int H = problem_.horizon;
    if (r.size() != 1 && r.size() != H) {
      return absl::InvalidArgumentError(
          absl::StrCat("reference: expected 1 or ", H, " values (the horizon), got ", r.size()));
    }
    for (Eigen::Index n = 0; n < r.size(); ++n) {
      if (!std::isfinite(r(n)))
        return absl::InvalidArgumentError(absl::StrCat("reference[", n, "] = ", r(n), ": must be finite"));
    }
    // The reference lives in the output means of steps 1..H (see the header).
    for (int n = 0; n < H; ++n) shape_.mutable_output_prior(n + 1, 0).mean = r.size() == H ? r(n) : r(0);
    ReadReference(&reference_);
  }
  return update.state.has_value() ? SetInitialState(*update.state) : absl::OkStatus();
}

absl::StatusOr<core::SolveSummary> GpMpcSession::Solve(const core::SolveLimits& limits, core::Solution* solution) {
  NUPMPC_RETURN_IF_ERROR(core::Validate(limits));
  if (!limits.warm_start) {
    scp_->ResetWarmStart();
    solved_ = false;
  }
  NUPMPC_ASSIGN_OR_RETURN(const ScpSummary scp, scp_->Solve(past_outputs_, past_inputs_, reference_, &plan_, &limits));
  core::SolveSummary summary;
  summary.status = scp.status;
  summary.algorithm = core::Algorithm::kIffbdd;
  summary.iterations = scp.inner_passes;
  summary.linearisations = scp.iterations;
  summary.objective = scp.objective;
  summary.max_violation = scp.max_violation;
  summary.warm_started = solved_;
  summary.solve_seconds = scp.seconds;
  // A plan for this step's state only if the SCP accepted an iterate in this solve or
  // converged; a cancelled solve returns none.
  summary.has_plan = scp.has_plan && scp.status != core::SolveStatus::kCancelled;
  if (!summary.has_plan) {
    summary.objective = summary.max_violation = std::numeric_limits<double>::quiet_NaN();
  }
  solved_ = true;
  if (solution != nullptr) {
    if (summary.has_plan) {
      FillSolution(plan_, solution);
    } else {
      *solution = core::Solution{};
    }
  }
  return summary;
}

void GpMpcSession::FillSolution(const ScpPlan& plan, core::Solution* solution) const {
  const int H = problem_.horizon, l = problem_.layout.output_lags, m = problem_.layout.input_lags;
  solution->inputs = plan.inputs;
  solution->outputs.resize(H + 1, 1);
  solution->output_stddev.resize(H + 1, 1);
  solution->outputs(0, 0) = past_outputs_(l - 1);
  solution->output_stddev(0, 0) = 0.0;
  solution->outputs.col(0).tail(H) = plan.means;
  solution->output_stddev.col(0).tail(H) = plan.sigmas;
  // The window slides along the plan: outputs and inputs, measured then planned.
  Eigen::VectorXd y(l + H), u(m + 1 + H);
  y << past_outputs_, plan.means;
  u << past_inputs_, plan.inputs;
  solution->states.resize(H + 1, l + m + 1);
  for (int n = 0; n <= H; ++n) {
    solution->states.row(n).head(l) = y.segment(n, l).transpose();
    solution->states.row(n).tail(m + 1) = u.segment(n, m + 1).transpose();
  }
}

}  // namespace nupmpc::gp
