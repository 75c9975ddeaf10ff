#include "core/gp/hyperparameter_fit.h"

#include <chrono>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "ceres/gradient_problem.h"
#include "ceres/gradient_problem_solver.h"
#include "ceres/iteration_callback.h"

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

class LogLikelihoodCost final : public ceres::FirstOrderFunction {
 public:
  LogLikelihoodCost(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets, double min_noise)
      : inputs_(inputs), targets_(targets), min_noise_(min_noise) {}
  bool Evaluate(const double* parameters, double* cost, double* gradient) const override {
    const int d = static_cast<int>(inputs_.cols());
    Eigen::VectorXd g;
    absl::StatusOr<double> nll =
        NegativeLogLikelihood(inputs_, targets_, FromLog(parameters, d, min_noise_), gradient ? &g : nullptr);
    if (!nll.ok() || !std::isfinite(*nll)) return false;  // Ceres backs off
    *cost = *nll;
    if (gradient != nullptr) Eigen::Map<Eigen::VectorXd>(gradient, d + 2) = g;
    return true;
  }
  int NumParameters() const override { return static_cast<int>(inputs_.cols()) + 2; }

 private:
  const Eigen::MatrixXd& inputs_;
  const Eigen::VectorXd& targets_;
  double min_noise_;
};

}  // namespace

absl::StatusOr<double> NegativeLogLikelihood(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& kernel, Eigen::VectorXd* log_gradient) {
  const int n = static_cast<int>(inputs.rows()), d = static_cast<int>(inputs.cols());
  if (absl::Status valid = Validate(kernel, d); !valid.ok()) return valid;
  if (targets.size() != n) return absl::InvalidArgumentError("targets: one value per input row");
  const Eigen::MatrixXd k_f = KernelMatrix(kernel, inputs);
  Eigen::MatrixXd k_y = k_f;
  k_y.diagonal().array() += kernel.noise_variance;
  const Eigen::LLT<Eigen::MatrixXd> llt(k_y);
  if (llt.info() != Eigen::Success) return absl::FailedPreconditionError("K + σ_n² I is not positive definite");
  const Eigen::VectorXd alpha = llt.solve(targets);
  const double log_det = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
  const double nll = 0.5 * targets.dot(alpha) + 0.5 * log_det + 0.5 * n * std::log(2.0 * std::numbers::pi);
  if (log_gradient != nullptr) {
    // Q = α αᵀ - K_y⁻¹; ∂NLL/∂θ = -½ Σ_ij Q_ij (∂K_y/∂θ)_ij.
    Eigen::MatrixXd q = -llt.solve(Eigen::MatrixXd::Identity(n, n));
    q.noalias() += alpha * alpha.transpose();
    log_gradient->resize(d + 2);
    (*log_gradient)(0) = -0.5 * q.cwiseProduct(k_f).sum();                  // ∂K/∂log σ_f² = K_f
    (*log_gradient)(d + 1) = -0.5 * kernel.noise_variance * q.trace();      // ∂K/∂log σ_n² = σ_n² I
    for (int i = 0; i < d; ++i) {
      // ∂K_f/∂log ℓ_i = K_f ⊙ (x_i - x'_i)²/ℓ_i²
      const double inv = 1.0 / (kernel.length_scales(i) * kernel.length_scales(i));
      double sum = 0.0;
      for (int b = 0; b < n; ++b) {
        for (int a = 0; a < n; ++a) {
          const double diff = inputs(a, i) - inputs(b, i);
          sum += q(a, b) * k_f(a, b) * diff * diff * inv;
        }
      }
      (*log_gradient)(1 + i) = -0.5 * sum;
    }
  }
  return nll;
}

namespace {
// Ends the fit after the current iteration once the flag is raised.
class CancelCallback : public ceres::IterationCallback {
 public:
  explicit CancelCallback(const std::atomic<bool>* cancel) : cancel_(cancel) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary&) override {
    return cancel_ != nullptr && cancel_->load(std::memory_order_relaxed) ? ceres::SOLVER_ABORT
                                                                          : ceres::SOLVER_CONTINUE;
  }

 private:
  const std::atomic<bool>* cancel_;
};
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
  const auto start = std::chrono::steady_clock::now();
  FitResult result;
  Eigen::VectorXd theta = ToLog(initial);
  absl::StatusOr<double> first = NegativeLogLikelihood(inputs, targets, initial, nullptr);
  if (!first.ok()) return first.status();
  result.initial_negative_log_likelihood = *first;

  ceres::GradientProblem problem(new LogLikelihoodCost(inputs, targets, options.min_noise_variance));
  ceres::GradientProblemSolver::Options solver_options;
  solver_options.line_search_direction_type = ceres::LBFGS;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.logging_type = ceres::SILENT;
  if (options.max_seconds > 0.0) solver_options.max_solver_time_in_seconds = options.max_seconds;
  CancelCallback cancel(options.cancel);
  if (options.cancel != nullptr) solver_options.callbacks.push_back(&cancel);
  ceres::GradientProblemSolver::Summary summary;
  ceres::Solve(solver_options, problem, theta.data(), &summary);
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.stopped = summary.termination_type == ceres::USER_FAILURE ||
                   (options.max_seconds > 0.0 && summary.termination_type == ceres::NO_CONVERGENCE &&
                    elapsed >= options.max_seconds);

  result.kernel = FromLog(theta.data(), d, options.min_noise_variance);
  Eigen::VectorXd gradient;
  absl::StatusOr<double> nll = NegativeLogLikelihood(inputs, targets, result.kernel, &gradient);
  if (!nll.ok()) return nll.status();
  result.negative_log_likelihood = *nll;
  result.gradient_norm = gradient.cwiseAbs().maxCoeff();
  result.iterations = static_cast<int>(summary.iterations.size());
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.report = summary.BriefReport();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace nupmpc::gp
