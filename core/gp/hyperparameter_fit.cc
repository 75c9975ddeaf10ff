#include "core/gp/hyperparameter_fit.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/gp/blocked_cholesky.h"
#include "core/util/status_macros.h"
#include "lbfgs.h"

namespace nupmpc::gp {
namespace {

// θ = [log σ_f², log ℓ_1..ℓ_d, log σ_n²]
Eigen::VectorXd ToLog(const SeArdKernel& k) {
  const Eigen::Index d = k.length_scales.size();
  Eigen::VectorXd theta(d + 2);
  theta(0) = std::log(k.signal_variance);
  theta.segment(1, d) = k.length_scales.array().log().matrix();
  theta(d + 1) = std::log(k.noise_variance);
  return theta;
}

SeArdKernel FromLog(const double* theta, int d, double min_noise) {
  SeArdKernel k;
  k.signal_variance = std::exp(theta[0]);
  k.length_scales.resize(d);
  for (int i = 0; i < d; ++i) k.length_scales(i) = std::exp(theta[1 + i]);
  k.noise_variance = std::max(std::exp(theta[d + 1]), min_noise);
  return k;
}

}  // namespace

absl::StatusOr<double> NegativeLogLikelihood(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& kernel, Eigen::VectorXd* log_gradient) {
  LikelihoodWorkspace workspace;
  return NegativeLogLikelihood(inputs, targets, kernel, log_gradient, core::Deadline{}, &workspace);
}

absl::StatusOr<double> NegativeLogLikelihood(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& kernel, Eigen::VectorXd* log_gradient,
                                             const core::Deadline& stop, LikelihoodWorkspace* workspace) {
  const int n = static_cast<int>(inputs.rows()), d = static_cast<int>(inputs.cols());
  if (absl::Status valid = Validate(kernel, d); !valid.ok()) return valid;
  if (targets.size() != n) return absl::InvalidArgumentError("targets: one value per input row");
  LikelihoodWorkspace& w = *workspace;
  NUPMPC_RETURN_IF_ERROR(FillKernelMatrix(kernel, inputs, stop, &w.kernel, &w.scaled));
  if (w.factor.rows() != n || w.factor.cols() != n) w.factor.resize(n, n);
  w.factor.triangularView<Eigen::Lower>() = w.kernel;
  w.factor.diagonal().array() += kernel.noise_variance;
  if (absl::Status s = BlockedCholesky(w.factor, stop, "K + σ_n² I"); !s.ok()) {
    if (s.code() == absl::StatusCode::kFailedPrecondition) {
      return absl::FailedPreconditionError("K + σ_n² I is not positive definite");
    }
    return s;
  }
  auto l = w.factor.triangularView<Eigen::Lower>();
  w.alpha = targets;
  l.solveInPlace(w.alpha);
  l.transpose().solveInPlace(w.alpha);
  const double log_det = 2.0 * w.factor.diagonal().array().log().sum();
  const double nll = 0.5 * targets.dot(w.alpha) + 0.5 * log_det + 0.5 * n * std::log(2.0 * std::numbers::pi);
  if (log_gradient == nullptr) return nll;

  // ∂NLL/∂θ = -½ Σ_ab Q_ab (∂K_y/∂θ)_ab with Q = α αᵀ - K_y⁻¹, both symmetric: the sums run
  // over the lower triangle (off-diagonal terms twice). ∂K/∂log σ_f² = K_f,
  // ∂K/∂log σ_n² = σ_n² I, ∂K_f/∂log ℓ_i = K_f ⊙ (x_i - x'_i)²/ℓ_i².
  if (w.row_block.rows() != kCholeskyBlock || w.row_block.cols() != n + kCholeskyBlock) {
    w.row_block.resize(kCholeskyBlock, n + kCholeskyBlock);
  }
  NUPMPC_RETURN_IF_ERROR(InverseFromCholesky(w.factor, &w.row_block, stop, "K + σ_n² I"));
  log_gradient->setZero(d + 2);
  double trace = 0.0;
  constexpr int kColumns = 64;  // per check: O(N d kColumns)
  for (int b = 0; b < n; ++b) {
    if (b % kColumns == 0 && stop.Requested()) {
      return stop.Stopped(absl::StrCat("summing the likelihood gradient (column ", b, " of ", n, ")"));
    }
    const int rows = n - b;
    const auto q = w.alpha.segment(b, rows).array() * w.alpha(b) - w.factor.col(b).tail(rows).array();
    const auto qk = q * w.kernel.col(b).tail(rows).array();
    trace += q(0);
    (*log_gradient)(0) += 2.0 * qk.sum() - qk(0);
    for (int i = 0; i < d; ++i) {
      // The diagonal term has x_i - x'_i = 0: no correction for counting it twice.
      (*log_gradient)(1 + i) += 2.0 * (qk * (inputs.col(i).tail(rows).array() - inputs(b, i)).square()).sum();
    }
  }
  (*log_gradient)(0) *= -0.5;
  (*log_gradient)(d + 1) = -0.5 * kernel.noise_variance * trace;
  for (int i = 0; i < d; ++i) {
    (*log_gradient)(1 + i) *= -0.5 / (kernel.length_scales(i) * kernel.length_scales(i));
  }
  return nll;
}

namespace {

// One fit's state, reached from liblbfgs' C callbacks through their `instance` pointer.
struct FitRun {
  FitRun(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets, const FitOptions& options)
      : inputs(inputs),
        targets(targets),
        options(options),
        start(std::chrono::steady_clock::now()),
        stop(core::Deadline::After(options.max_seconds, options.cancel)) {}

  const Eigen::MatrixXd& inputs;
  const Eigen::VectorXd& targets;
  const FitOptions& options;
  std::chrono::steady_clock::time_point start;
  core::Deadline stop;  // max_seconds from the start, and the cancel flag
  LikelihoodWorkspace workspace;
  Eigen::VectorXd gradient;  // NegativeLogLikelihood's output, reused across evaluations
  double previous_nll = std::numeric_limits<double>::infinity();
  // The NLL and gradient max-norm at the iterate liblbfgs will return (the last one it
  // accepted, or the start): known without evaluating it again.
  bool accepted_known = false;
  double accepted_nll = 0.0;
  double accepted_gradient_max = 0.0;
  int evaluations = 0;
  int iterations = 0;
  bool converged = false;
  bool stopped = false;

  void Accept(double nll, double gradient_max) {
    accepted_known = true;
    accepted_nll = nll;
    accepted_gradient_max = gradient_max;
  }

  bool MustStop() const { return stop.Requested(); }
  // The status of an evaluation `stop` ended (it then stops the fit).
  static bool Interrupted(const absl::Status& status) {
    return status.code() == absl::StatusCode::kDeadlineExceeded || status.code() == absl::StatusCode::kCancelled;
  }
};

// A point where K_y is not positive definite evaluates to +inf, and so does every point
// once the fit must stop: the backtracking line search then shortens its step, and gives up
// after a few calls that cost nothing instead of O(P³) each. Whatever ends the fit,
// liblbfgs leaves the last iterate it accepted in its variables.
lbfgsfloatval_t EvaluateNll(void* instance, const lbfgsfloatval_t* theta, lbfgsfloatval_t* gradient, int n,
                            lbfgsfloatval_t /*step*/) {
  FitRun& run = *static_cast<FitRun*>(instance);
  Eigen::Map<Eigen::VectorXd> g(gradient, n);
  g.setZero();
  if (run.MustStop()) {
    run.stopped = true;
    return std::numeric_limits<double>::infinity();
  }
  const absl::StatusOr<double> nll =
      NegativeLogLikelihood(run.inputs, run.targets, FromLog(theta, n - 2, run.options.min_noise_variance),
                            &run.gradient, run.stop, &run.workspace);
  if (!nll.ok() && FitRun::Interrupted(nll.status())) {
    run.stopped = true;  // inside the evaluation: the line search gives up as above
    return std::numeric_limits<double>::infinity();
  }
  if (!nll.ok() || !std::isfinite(*nll) || !run.gradient.allFinite()) return std::numeric_limits<double>::infinity();
  g = run.gradient;
  if (run.evaluations++ == 0) run.Accept(*nll, run.gradient.cwiseAbs().maxCoeff());  // the start
  return *nll;
}

// Our own stopping tests (liblbfgs' are relative to ‖θ‖ and ill-defined for a negative
// NLL): the gradient's max-norm, or the relative decrease of the NLL in one iteration.
// A non-zero return ends the fit.
int AfterIteration(void* instance, const lbfgsfloatval_t* /*theta*/, const lbfgsfloatval_t* gradient,
                   lbfgsfloatval_t nll, lbfgsfloatval_t /*theta_norm*/, lbfgsfloatval_t /*gradient_norm*/,
                   lbfgsfloatval_t /*step*/, int n, int iteration, int /*evaluations*/) {
  FitRun& run = *static_cast<FitRun*>(instance);
  run.iterations = iteration;
  const double gradient_max = Eigen::Map<const Eigen::VectorXd>(gradient, n).cwiseAbs().maxCoeff();
  run.Accept(nll, gradient_max);
  const double decrease = run.previous_nll - nll;
  run.previous_nll = nll;
  if (gradient_max <= run.options.gradient_tolerance ||
      std::abs(decrease) <= run.options.function_tolerance * std::max(1.0, std::abs(nll))) {
    run.converged = true;
    return 1;
  }
  if (run.MustStop()) {
    run.stopped = true;
    return 1;
  }
  return 0;
}

std::string_view LbfgsOutcome(int code) {
  switch (code) {
    case LBFGS_SUCCESS:
      return "success";
    case LBFGS_STOP:
      return "stopping test met";
    case LBFGS_ALREADY_MINIMIZED:
      return "already minimal";
    case LBFGSERR_MAXIMUMITERATION:
      return "iteration limit";
    case LBFGSERR_MAXIMUMLINESEARCH:
      return "line search: evaluation limit";
    case LBFGSERR_MINIMUMSTEP:
      return "line search: step below minimum";
    case LBFGSERR_ROUNDING_ERROR:
      return "line search: rounding errors";
    case LBFGSERR_INCREASEGRADIENT:
      return "line search: gradient increases";
    default:
      return "line search failed";
  }
}

}  // namespace

absl::StatusOr<FitResult> FitHyperparameters(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& initial, const FitOptions& options) {
  const int d = static_cast<int>(inputs.cols());
  if (inputs.rows() < 2) return absl::InvalidArgumentError("inputs: need at least two points to fit");
  if (!inputs.allFinite() || !targets.allFinite()) return absl::InvalidArgumentError("inputs/targets: non-finite");
  if (absl::Status valid = Validate(initial, d); !valid.ok()) return valid;
  if (!(options.max_seconds >= 0.0)) {
    return absl::InvalidArgumentError(absl::StrCat("FitOptions.max_seconds = ", options.max_seconds, "; must be >= 0"));
  }
  if (options.max_iterations < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("FitOptions.max_iterations = ", options.max_iterations, "; must be >= 1"));
  }
  FitRun run(inputs, targets, options);
  FitResult result;
  const auto finish = [&](std::string_view outcome) {
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - run.start).count();
    result.report = absl::StrFormat("L-BFGS: %d iterations, NLL %.6g -> %.6g, |gradient|max %.3g, %s (%.3f s)",
                                    result.iterations, result.initial_negative_log_likelihood,
                                    result.negative_log_likelihood, result.gradient_norm, outcome, result.seconds);
    return result;
  };
  absl::StatusOr<double> first = NegativeLogLikelihood(inputs, targets, initial, nullptr, run.stop, &run.workspace);
  if (!first.ok() && FitRun::Interrupted(first.status())) {
    // Stopped inside the first evaluation: the start, with what is known of it.
    result.kernel = initial;
    result.initial_negative_log_likelihood = result.negative_log_likelihood = std::numeric_limits<double>::quiet_NaN();
    result.gradient_norm = std::numeric_limits<double>::quiet_NaN();
    result.stopped = true;
    return finish("stopped (time or cancel) in the first evaluation");
  }
  if (!first.ok()) return first.status();
  result.initial_negative_log_likelihood = *first;

  // liblbfgs may be built to need its own (aligned) allocation for the variables.
  const int n = d + 2;
  const std::unique_ptr<lbfgsfloatval_t, void (*)(lbfgsfloatval_t*)> theta(lbfgs_malloc(n), lbfgs_free);
  if (theta == nullptr) return absl::ResourceExhaustedError("hyper-parameter fit: out of memory");
  Eigen::Map<Eigen::VectorXd>(theta.get(), n) = ToLog(initial);
  lbfgs_parameter_t parameters;
  lbfgs_parameter_init(&parameters);
  parameters.max_iterations = options.max_iterations;
  parameters.linesearch = LBFGS_LINESEARCH_BACKTRACKING_WOLFE;  // copes with +inf (see EvaluateNll)
  parameters.epsilon = 0.0;                                     // AfterIteration decides convergence
  parameters.past = 0;
  lbfgsfloatval_t last_nll = 0.0;
  const int code = lbfgs(n, theta.get(), &last_nll, EvaluateNll, AfterIteration, &run, &parameters);

  result.kernel = FromLog(theta.get(), d, options.min_noise_variance);
  if (!run.accepted_known) {
    // Stopped before liblbfgs evaluated the start (so the kernel is the start): its NLL is
    // known, its gradient is not, and computing it now would hold the worker for another
    // O(P³) evaluation after the stop.
    run.Accept(result.initial_negative_log_likelihood, std::numeric_limits<double>::quiet_NaN());
  }
  result.negative_log_likelihood = run.accepted_nll;
  result.gradient_norm = run.accepted_gradient_max;
  result.iterations = run.iterations;
  result.converged = run.converged;
  result.stopped = !run.converged && run.stopped;
  return finish(result.converged ? "converged" : result.stopped ? "stopped (time or cancel)" : LbfgsOutcome(code));
}

}  // namespace nupmpc::gp
