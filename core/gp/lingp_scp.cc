#include "core/gp/lingp_scp.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include "absl/strings/str_cat.h"

namespace nupmpc::gp {
namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

constexpr int kOutputs = 4;                   // ȳ (tracking + trust), u (box ∩ trust), ȳ + κσ, ȳ - κσ
constexpr double kMinRelativeRadius = 1e-12;  // of max(1, |nominal|): the narrowest trust box

// Gradient of σ = sqrt(ξᵀ V̂ ξ) at ξ₀ = [1; 0] with respect to Δx: V̂[1:, 0] / σ.
Eigen::VectorXd SigmaGradient(const LinGp& lin, double* sigma) {
  *sigma = std::sqrt(std::max(lin.covariance(0, 0), 0.0));
  const Eigen::Index d = lin.covariance.rows() - 1;
  if (*sigma < 1e-12) return Eigen::VectorXd::Zero(d);
  return lin.covariance.col(0).tail(d) / *sigma;
}

}  // namespace

LinGpScp::LinGpScp(const GpModel* model, GpMpcProblem problem, ScpOptions options, core::Problem shape)
    : model_(model), p_(std::move(problem)), options_(options), problem_(std::move(shape)) {}

absl::StatusOr<std::unique_ptr<LinGpScp>> LinGpScp::Create(const GpModel* model, GpMpcProblem problem,
                                                           ScpOptions options) {
  if (model == nullptr) return absl::InvalidArgumentError("model: must not be null");
  if (absl::Status s = Validate(problem); !s.ok()) return s;
  if (absl::Status s = Validate(options); !s.ok()) return s;
  if (model->dimension() != problem.layout.dimension()) {
    return absl::InvalidArgumentError(absl::StrCat("GpMpcProblem.layout: regressor dimension ",
                                                   problem.layout.dimension(), " does not match the GP's ",
                                                   model->dimension()));
  }
  const int l = problem.layout.output_lags, m = problem.layout.input_lags, H = problem.horizon;
  const int M = (l + 1) + (m + 1);
  core::Problem shape;
  shape.num_states = M;
  shape.num_inputs = 1;
  shape.num_outputs = kOutputs;
  shape.horizon = H;
  shape.A.assign(H, Eigen::MatrixXd::Zero(M, M));
  shape.B.assign(H, Eigen::MatrixXd::Zero(M, 1));
  shape.state_offset.assign(H, Eigen::VectorXd::Zero(M));
  shape.C.assign(H + 1, Eigen::MatrixXd::Zero(kOutputs, M));
  shape.output_offset.assign(H + 1, Eigen::VectorXd::Zero(kOutputs));
  shape.initial_mean = Eigen::VectorXd::Zero(M);
  // Δu: the rate limit (hard) with the move cost R as its Gaussian part (½·2R·Δu²).
  shape.input_priors.assign(H, core::ScalarPrior::Box(problem.rate_min, problem.rate_max)
                                   .WithGaussian(0.0, 1.0 / (2.0 * problem.input_change_weight)));
  shape.output_priors.assign(static_cast<std::size_t>(H + 1) * kOutputs, core::ScalarPrior::Free());
  std::unique_ptr<LinGpScp> scp(new LinGpScp(model, std::move(problem), options, std::move(shape)));
  // Session::Create needs a valid problem: a neutral linearisation (nominal u ≡ 0).
  scp->past_outputs_ = Eigen::VectorXd::Zero(l);
  scp->past_inputs_ = Eigen::VectorXd::Zero(m + 1);
  scp->reference_ = Eigen::VectorXd::Zero(H);
  scp->nominal_u_ = Eigen::VectorXd::Zero(H);
  scp->Simulate(scp->nominal_u_, &scp->nominal_x_, &scp->nominal_y_, &scp->nominal_lin_);
  scp->BuildSubproblem(options.initial_trust_radius);
  absl::StatusOr<std::unique_ptr<core::Session>> session = core::Session::Create(scp->problem_);
  if (!session.ok()) return session.status();
  scp->session_ = *std::move(session);
  return scp;
}

double LinGpScp::UpperBound(int n) const {
  double bound = p_.output_max;
  if (n == p_.horizon - 1 && p_.terminal_tolerance > 0.0 && std::isfinite(p_.terminal_tolerance)) {
    bound = std::min(bound, reference_(n) + p_.terminal_tolerance);
  }
  return bound;
}

double LinGpScp::LowerBound(int n) const {
  double bound = p_.output_min;
  if (n == p_.horizon - 1 && p_.terminal_tolerance > 0.0 && std::isfinite(p_.terminal_tolerance)) {
    bound = std::max(bound, reference_(n) - p_.terminal_tolerance);
  }
  return bound;
}

void LinGpScp::Simulate(const Eigen::VectorXd& inputs, Eigen::MatrixXd* regressors, Eigen::VectorXd* means,
                        std::vector<LinGp>* lin) const {
  const int l = p_.layout.output_lags, m = p_.layout.input_lags, H = p_.horizon;
  Eigen::VectorXd y(l + H), u(m + 1 + H), x(p_.layout.dimension());
  y.head(l) = past_outputs_;
  u.head(m + 1) = past_inputs_;
  u.tail(H) = inputs;
  regressors->resize(H, p_.layout.dimension());
  means->resize(H);
  for (int n = 0; n < H; ++n) {
    // ȳ[t+n] from y[t+n-l..t+n-1] and u[t+n-m..t+n] (u's index is shifted by m+1).
    Regressor(p_.layout, y.segment(n, l), u.segment(n + 1, m + 1), &x);
    regressors->row(n) = x.transpose();
    y(l + n) = model_->Mean(x);
    (*means)(n) = y(l + n);
  }
  model_->Linearise(*regressors, lin, &scratch_);  // the exact σ² is each V̂(0, 0)
}

double LinGpScp::Merit(const Eigen::VectorXd& inputs, const Eigen::VectorXd& means, const Eigen::VectorXd& sigmas,
                       double* objective, double* max_violation) const {
  double j = 0.0, penalty = 0.0, worst = 0.0;
  double previous = past_inputs_(p_.layout.input_lags);
  for (int n = 0; n < p_.horizon; ++n) {
    const double e = means(n) - reference_(n), du = inputs(n) - previous;
    j += p_.output_weight * e * e + p_.input_change_weight * du * du;
    previous = inputs(n);
    const double over = std::max(0.0, means(n) + p_.sigma_multiple * sigmas(n) - UpperBound(n));
    const double under = std::max(0.0, LowerBound(n) - (means(n) - p_.sigma_multiple * sigmas(n)));
    penalty += over + under;
    worst = std::max({worst, over, under});
  }
  if (objective != nullptr) *objective = j;
  if (max_violation != nullptr) *max_violation = worst;
  return j + options_.penalty * penalty;
}

double LinGpScp::ExactMerit(const Eigen::VectorXd& inputs, ScpPlan* evaluated, double* objective,
                            double* max_violation) const {
  Eigen::MatrixXd regressors;
  Eigen::VectorXd means;
  std::vector<LinGp> lin;
  Simulate(inputs, &regressors, &means, &lin);
  Eigen::VectorXd sigmas(p_.horizon);
  for (int n = 0; n < p_.horizon; ++n) sigmas(n) = std::sqrt(std::max(lin[n].covariance(0, 0), 0.0));
  if (evaluated != nullptr) *evaluated = ScpPlan{inputs, means, sigmas};
  return Merit(inputs, means, sigmas, objective, max_violation);
}

void LinGpScp::BuildSubproblem(double rho) {
  const int l = p_.layout.output_lags, m = p_.layout.input_lags, H = p_.horizon, d = p_.layout.dimension();
  const int u_now = l + 1;  // state index of u[k]
  // Where regressor entry q lives in the state at step k: ȳ[k-i] at i, u[k-j] at l+1+j.
  const auto state_index = [&](int q) { return q < l ? l - q : l + 1 + (l + m - q); };
  // x[0] = [y[t-1], ..., y[t-l], (y[t-l], unused), u[t-1], ..., u[t-m-1]].
  for (int i = 0; i < l; ++i) problem_.initial_mean(i) = past_outputs_(l - 1 - i);
  problem_.initial_mean(l) = past_outputs_(0);
  for (int j = 0; j <= m; ++j) problem_.initial_mean(l + 1 + j) = past_inputs_(m - j);

  for (int n = 0; n < H; ++n) {
    const LinGp& lin = nominal_lin_[n];
    const auto g = lin.mean.tail(d);                    // ∇μ at the nominal regressor
    const auto x_star = nominal_x_.row(n).transpose();  // the nominal regressor
    Eigen::MatrixXd& A = problem_.A[n];
    Eigen::MatrixXd& B = problem_.B[n];
    Eigen::VectorXd& c = problem_.state_offset[n];
    A.setZero();
    B.setZero();
    c.setZero();
    // ȳ[k] = μ* + gᵀ(reg - reg*), the regressor read from x[n] (one step older) and Δu.
    for (int q = 0; q < d; ++q) {
      if (q < l) {
        A(0, (l - q) - 1) += g(q);  // ȳ[k-i] is x[n](i-1)
      } else if (const int j = l + m - q; j >= 1) {
        A(0, l + 1 + j - 1) += g(q);  // u[k-j] is x[n](l+1+j-1)
      } else {
        A(0, u_now) += g(q);  // u[k] = u[k-1] + Δu
        B(0, 0) += g(q);
      }
    }
    c(0) = lin.mean(0) - g.dot(x_star);
    for (int i = 1; i <= l; ++i) A(i, i - 1) = 1.0;  // shift the outputs
    A(u_now, u_now) = 1.0;                           // u[k] = u[k-1] + Δu
    B(u_now, 0) = 1.0;
    for (int j = 1; j <= m; ++j) A(l + 1 + j, l + 1 + j - 1) = 1.0;  // shift the inputs

    // Outputs at x[n+1] (step k = t+n).
    double sigma = 0.0;
    const Eigen::VectorXd gs = SigmaGradient(lin, &sigma);
    Eigen::MatrixXd& C = problem_.C[n + 1];
    Eigen::VectorXd& offset = problem_.output_offset[n + 1];
    C.setZero();
    C(0, 0) = 1.0;
    C(1, u_now) = 1.0;
    C(2, 0) = 1.0;
    C(3, 0) = 1.0;
    for (int q = 0; q < d; ++q) {
      C(2, state_index(q)) += p_.sigma_multiple * gs(q);
      C(3, state_index(q)) -= p_.sigma_multiple * gs(q);
    }
    offset.setZero();
    offset(2) = p_.sigma_multiple * (sigma - gs.dot(x_star));
    offset(3) = -offset(2);

    // The trust boxes are at least a few rounding units of the nominal wide: a radius below
    // that would give lower == upper, which the core refuses.
    const double y_star = nominal_y_(n), u_star = nominal_u_(n);
    const double rho_y = std::max(rho, kMinRelativeRadius * std::max(1.0, std::abs(y_star)));
    const double rho_u = std::max(rho, kMinRelativeRadius * std::max(1.0, std::abs(u_star)));
    problem_.mutable_output_prior(n + 1, 0) = core::ScalarPrior::Box(y_star - rho_y, y_star + rho_y)
                                                  .WithGaussian(reference_(n), 1.0 / (2.0 * p_.output_weight));
    problem_.mutable_output_prior(n + 1, 1) =
        core::ScalarPrior::Box(std::max(p_.input_min, u_star - rho_u), std::min(p_.input_max, u_star + rho_u));
    // An infinite output bound is no constraint on that side (the .proto allows ±Infinity).
    const double upper = UpperBound(n), lower = LowerBound(n);
    problem_.mutable_output_prior(n + 1, 2) =
        std::isfinite(upper) ? core::ScalarPrior::AtMost(upper, options_.penalty) : core::ScalarPrior::Free();
    problem_.mutable_output_prior(n + 1, 3) =
        std::isfinite(lower) ? core::ScalarPrior::AtLeast(lower, options_.penalty) : core::ScalarPrior::Free();
  }
}

void LinGpScp::ProjectToInputConstraints(Eigen::VectorXd* inputs) const {
  double previous = past_inputs_(p_.layout.input_lags);
  for (Eigen::Index n = 0; n < inputs->size(); ++n) {
    const double lo = std::max(p_.input_min, previous + p_.rate_min);
    const double hi = std::min(p_.input_max, previous + p_.rate_max);
    (*inputs)(n) = std::clamp((*inputs)(n), std::min(lo, hi), std::max(lo, hi));
    previous = (*inputs)(n);
  }
}

void LinGpScp::ShiftWarmStart() {
  if (!has_warm_) return;
  const int H = p_.horizon;
  for (int n = 0; n + 1 < H; ++n) nominal_u_(n) = nominal_u_(n + 1);
  session_->ShiftWarmStart();
}

absl::StatusOr<ScpSummary> LinGpScp::Solve(const Eigen::VectorXd& past_outputs, const Eigen::VectorXd& past_inputs,
                                           const Eigen::VectorXd& reference, ScpPlan* plan,
                                           const core::SolveLimits* outer_limits) {
  const int l = p_.layout.output_lags, m = p_.layout.input_lags, H = p_.horizon;
  if (past_outputs.size() != l) {
    return absl::InvalidArgumentError(absl::StrCat("past_outputs: expected ", l, " values, got ", past_outputs.size()));
  }
  if (past_inputs.size() != m + 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("past_inputs: expected ", m + 1, " values, got ", past_inputs.size()));
  }
  if (reference.size() != H && reference.size() != 1) {
    return absl::InvalidArgumentError(absl::StrCat("reference: expected ", H, " values or 1, got ", reference.size()));
  }
  if (!past_outputs.allFinite() || !past_inputs.allFinite() || !reference.allFinite()) {
    return absl::InvalidArgumentError("past_outputs/past_inputs/reference: contain a non-finite number");
  }
  if (outer_limits != nullptr) {
    if (absl::Status s = core::Validate(*outer_limits); !s.ok()) return s;
  }
  const auto start = Clock::now();
  past_outputs_ = past_outputs;
  past_inputs_ = past_inputs;
  reference_ = reference.size() == H ? reference : Eigen::VectorXd::Constant(H, reference(0));

  Eigen::VectorXd sigmas(H);
  const auto sigmas_of = [&](const std::vector<LinGp>& lin) {
    for (int n = 0; n < H; ++n) sigmas(n) = std::sqrt(std::max(lin[n].covariance(0, 0), 0.0));
    return sigmas;
  };
  // A feasible nominal plan: the warm one, clipped to the input box and rate-limited
  // from u[t-1], so that the first subproblem (which contains it) is feasible. Without a
  // warm plan, the best of a few input levels held over the horizon (exact merit): a
  // stationary point of the model (here u³ has zero slope at u = 0) would otherwise hold
  // the SCP, whose steps only see first-order information, where it started.
  double merit = 0.0;
  if (has_warm_) {
    ProjectToInputConstraints(&nominal_u_);
    Simulate(nominal_u_, &nominal_x_, &nominal_y_, &nominal_lin_);
    merit = Merit(nominal_u_, nominal_y_, sigmas_of(nominal_lin_), nullptr, nullptr);
  } else {
    merit = std::numeric_limits<double>::infinity();
    for (int level = -1; level < options_.cold_start_levels; ++level) {
      // level -1: u[t-1] held; then evenly spaced levels of the input box.
      const double value = level < 0 ? past_inputs_(m)
                                     : p_.input_min + (p_.input_max - p_.input_min) * level /
                                                          std::max(1, options_.cold_start_levels - 1);
      candidate_u_ = Eigen::VectorXd::Constant(H, value);
      ProjectToInputConstraints(&candidate_u_);
      Simulate(candidate_u_, &candidate_x_, &candidate_y_, &candidate_lin_);
      const double candidate_merit = Merit(candidate_u_, candidate_y_, sigmas_of(candidate_lin_), nullptr, nullptr);
      if (candidate_merit < merit) {
        merit = candidate_merit;
        std::swap(nominal_u_, candidate_u_);
        std::swap(nominal_x_, candidate_x_);
        std::swap(nominal_y_, candidate_y_);
        std::swap(nominal_lin_, candidate_lin_);
      }
    }
  }

  ScpSummary summary;
  double rho = options_.initial_trust_radius;
  core::SolveLimits limits;
  limits.warm_start = has_warm_;
  const core::SolveLimits outer = outer_limits != nullptr ? *outer_limits : core::SolveLimits{};
  const int max_iterations =
      outer.max_iterations > 0 ? std::min(options_.max_iterations, outer.max_iterations) : options_.max_iterations;
  limits.cancel = outer.cancel;
  // Checked before each SCP iteration; the inner solve gets the time that is left.
  const auto stop_requested = [&]() {
    const double elapsed = SecondsSince(start);
    const std::optional<core::SolveStatus> stop = core::LimitReached(outer, elapsed);
    if (stop.has_value()) summary.status = *stop;
    if (outer.time_limit_seconds > 0.0) limits.time_limit_seconds = outer.time_limit_seconds - elapsed;
    return stop.has_value();
  };
  for (int j = 0; j < max_iterations; ++j) {
    if (stop_requested()) break;
    BuildSubproblem(rho);
    if (absl::Status updated = session_->Update(problem_); !updated.ok()) {
      return absl::Status(updated.code(), absl::StrCat("SCP iteration ", j, ": ", updated.message()));
    }
    const auto inner_start = Clock::now();
    absl::StatusOr<core::SolveSummary> inner = session_->Solve(limits, &solution_);
    summary.inner_seconds += SecondsSince(inner_start);
    if (!inner.ok()) return inner.status();
    limits.warm_start = true;
    ++summary.iterations;
    summary.inner_passes += inner->iterations;
    if (inner->status == core::SolveStatus::kCancelled || inner->status == core::SolveStatus::kTimeLimit) {
      // An unfinished subproblem's plan may violate its hard constraints: keep the nominal.
      summary.status = inner->status;
      break;
    }
    if (!inner->has_plan) {
      rho *= options_.beta_fail;
      if (rho < options_.min_trust_radius) break;
      continue;
    }
    // Predicted merit ϕ̃ of the subproblem's plan (linGP mean, linearised σ).
    candidate_u_.resize(H);
    double predicted = 0.0, previous_u = past_inputs_(m);
    for (int n = 0; n < H; ++n) {
      candidate_u_(n) = solution_.states(n + 1, l + 1);
      const double e = solution_.outputs(n + 1, 0) - reference_(n), du = candidate_u_(n) - previous_u;
      previous_u = candidate_u_(n);
      predicted += p_.output_weight * e * e + p_.input_change_weight * du * du +
                   options_.penalty * (std::max(0.0, solution_.outputs(n + 1, 2) - UpperBound(n)) +
                                       std::max(0.0, LowerBound(n) - solution_.outputs(n + 1, 3)));
    }
    const double predicted_reduction = merit - predicted;
    if (std::abs(predicted_reduction) <= options_.tolerance) {
      summary.converged = true;
      summary.status = core::SolveStatus::kConverged;
      break;
    }
    // The subproblem meets its hard boxes to the solver's tolerance (~1e-12): project, so
    // that every accepted plan satisfies the input and rate limits exactly.
    ProjectToInputConstraints(&candidate_u_);
    Simulate(candidate_u_, &candidate_x_, &candidate_y_, &candidate_lin_);
    const double candidate_merit = Merit(candidate_u_, candidate_y_, sigmas_of(candidate_lin_), nullptr, nullptr);
    const double ratio = (merit - candidate_merit) / predicted_reduction;
    if (ratio < options_.r0) {
      rho *= options_.beta_fail;  // reject: keep the nominal plan
    } else {
      std::swap(nominal_u_, candidate_u_);
      std::swap(nominal_x_, candidate_x_);
      std::swap(nominal_y_, candidate_y_);
      std::swap(nominal_lin_, candidate_lin_);
      merit = candidate_merit;
      ++summary.accepted;
      if (ratio < options_.r1) {
        rho *= options_.beta_fail;
      } else if (ratio >= options_.r2) {
        rho = std::min(rho * options_.beta_success, options_.max_trust_radius);
      }
    }
    if (rho < options_.min_trust_radius) break;
  }
  summary.merit = Merit(nominal_u_, nominal_y_, sigmas_of(nominal_lin_), &summary.objective, &summary.max_violation);
  summary.trust_radius = rho;
  // The nominal plan is this solve's only if a step was accepted or the SCP converged
  // (else it is the previous plan shifted, or a constant guess).
  summary.has_plan = summary.accepted > 0 || summary.converged;
  has_warm_ = true;
  if (plan != nullptr) *plan = ScpPlan{nominal_u_, nominal_y_, sigmas};
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace nupmpc::gp
