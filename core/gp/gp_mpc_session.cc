#include "core/gp/gp_mpc_session.h"

#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::gp {
namespace {

// Every field but the Gaussian mean (the reference lives there).
bool SameExceptMean(const core::ScalarPrior& a, const core::ScalarPrior& b) {
  return a.kind == b.kind && a.variance == b.variance && a.lower == b.lower && a.upper == b.upper &&
         a.slope == b.slope && a.radius == b.radius && a.exponent == b.exponent && a.em == b.em &&
         a.initial_variance == b.initial_variance && a.rounds_with_next == b.rounds_with_next;
}

}  // namespace

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

absl::Status GpMpcSession::Update(const core::Problem& problem) {
  NUPMPC_RETURN_IF_ERROR(core::CheckSameShape(shape_, problem));
  for (std::size_t i = 0; i < shape_.input_priors.size(); ++i) {
    const core::ScalarPrior &now = shape_.input_priors[i], &next = problem.input_priors[i];
    if (!SameExceptMean(now, next) || now.mean != next.mean) {
      return absl::FailedPreconditionError(absl::StrCat(
          "input_priors[", i, "]: a GP session's input box is fixed at creation (only the reference changes)"));
    }
  }
  for (std::size_t i = 0; i < shape_.output_priors.size(); ++i) {
    const bool measured_step = i == 0;  // y[0] is measured: no prior to change
    if (!SameExceptMean(shape_.output_priors[i], problem.output_priors[i]) ||
        (measured_step && shape_.output_priors[i].mean != problem.output_priors[i].mean)) {
      return absl::FailedPreconditionError(absl::StrCat(
          "output_priors[", i, "]: a GP session takes new reference values (targets of steps 1..H) only"));
    }
    if (!std::isfinite(problem.output_priors[i].mean)) {
      return absl::InvalidArgumentError(absl::StrCat("output_priors[", i, "].mean: must be finite"));
    }
  }
  NUPMPC_RETURN_IF_ERROR(core::CheckInitialState(shape_, problem.initial_mean));
  shape_.output_priors = problem.output_priors;
  ReadReference(&reference_);
  return SetInitialState(problem.initial_mean);
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
