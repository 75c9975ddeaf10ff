#ifndef NUPMPC_CORE_GP_HYPERPARAMETER_FIT_H_
#define NUPMPC_CORE_GP_HYPERPARAMETER_FIT_H_

// Maximum-likelihood hyper-parameters of a squared-exponential ARD GP: minimises the
// negative log marginal likelihood
//   NLL(θ) = ½ Yᵀ K_y⁻¹ Y + ½ log det K_y + (N/2) log 2π,   K_y = K + σ_n² I
// over θ = log(σ_f², ℓ_1..ℓ_d, σ_n²) with its analytic gradient
//   ∂NLL/∂θ_j = -½ tr((α αᵀ - K_y⁻¹) ∂K_y/∂θ_j)          (Rasmussen & Williams (5.9))
// by L-BFGS (liblbfgs, a C library: it shares no C++ or Eigen types with us, so no
// inline Eigen code compiled with other alignment settings can enter our link). O(N³) per
// evaluation (a Cholesky factor and an inverse from it, each about N³/3 multiply-adds):
// fit on a few hundred points; the model for more data reuses the hyper-parameters.

#include <atomic>
#include <string>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"
#include "core/public/deadline.h"

namespace nupmpc::gp {

struct FitOptions {
  int max_iterations = 200;
  double gradient_tolerance = 1e-8;
  double function_tolerance = 1e-10;
  // Lower bound on σ_n² (keeps K_y well conditioned on noise-free data).
  double min_noise_variance = 1e-8;
  // Wall time for the whole fit (0: none) and a flag, both checked before every likelihood
  // evaluation and between the blocks of work inside one (kernel matrix, Cholesky factor,
  // inverse, gradient sums): one evaluation costs O(P³) for P points, and a service must
  // be able to stop the fit within a small fraction of one.
  double max_seconds = 0.0;
  const std::atomic<bool>* cancel = nullptr;
};

struct FitResult {
  SeArdKernel kernel;
  double negative_log_likelihood = 0.0;
  double initial_negative_log_likelihood = 0.0;
  int iterations = 0;
  bool converged = false;  ///< a stopping test (gradient or function tolerance) was met
  bool stopped = false;    ///< max_seconds or the cancel flag ended it (kernel: the start's or the last step's)
  // Max-norm of the gradient in log parameters at the end; NaN when a stop came before it
  // was known (then also the NLLs, if it came inside the first evaluation).
  double gradient_norm = 0.0;
  double seconds = 0.0;
  std::string report;  ///< one line: iterations, NLL before and after, how it ended
};

// The buffers of one likelihood evaluation (three P × P matrices at most), reused by every
// evaluation of a fit so that its iterations do not allocate.
struct LikelihoodWorkspace {
  Eigen::MatrixXd kernel;     ///< K_f
  Eigen::MatrixXd factor;     ///< the Cholesky factor of K_y, then the lower triangle of K_y⁻¹
  Eigen::MatrixXd scaled;     ///< FillKernelMatrix's scratch
  Eigen::MatrixXd row_block;  ///< InverseFromCholesky's scratch
  Eigen::VectorXd alpha;      ///< K_y⁻¹ Y
};

// NLL and its gradient with respect to log(σ_f², ℓ, σ_n²) (exposed for tests).
absl::StatusOr<double> NegativeLogLikelihood(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& kernel, Eigen::VectorXd* log_gradient);
// The same in `workspace`, stopped by `stop` (DEADLINE_EXCEEDED / CANCELLED saying where).
absl::StatusOr<double> NegativeLogLikelihood(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& kernel, Eigen::VectorXd* log_gradient,
                                             const core::Deadline& stop, LikelihoodWorkspace* workspace);

absl::StatusOr<FitResult> FitHyperparameters(const Eigen::MatrixXd& inputs, const Eigen::VectorXd& targets,
                                             const SeArdKernel& initial, const FitOptions& options = {});

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_HYPERPARAMETER_FIT_H_
