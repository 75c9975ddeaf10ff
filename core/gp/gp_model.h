#ifndef NUPMPC_CORE_GP_GP_MODEL_H_
#define NUPMPC_CORE_GP_GP_MODEL_H_

// Gaussian-process regression with a squared-exponential ARD kernel and zero prior mean
// (Rasmussen & Williams ch. 2; [Nghiem] §II):
//
//   k(x, x') = σ_f² exp(-½ Σ_i (x_i - x'_i)² / ℓ_i²),   y = f(x) + ε,  ε ~ N(0, σ_n²)
//
// The Cholesky factor of K + σ_n² I and α = (K + σ_n² I)⁻¹ Y are computed once per model
// (Create) and reused by every prediction. Predictions are of the latent f (no noise
// term), as in [Nghiem] (1).
//
// The linGP ([Nghiem] (3)–(6)): at a point x, f̂ = [f(x); ∇f(x)] is Gaussian with mean
// m̂ and covariance V̂; the linearised process f(x + Δ) ≈ [1; Δ]ᵀ f̂ has mean m̂ᵀ[1; Δ]
// (the exact mean's first-order Taylor expansion: the mean of the gradient is the
// gradient of the mean) and variance [1; Δ]ᵀ V̂ [1; Δ], convex in Δ.

#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "absl/status/statusor.h"

namespace nupmpc::gp {

struct SeArdKernel {
  double signal_variance = 1.0;  ///< σ_f² > 0
  Eigen::VectorXd length_scales;  ///< ℓ_i > 0, one per regressor
  double noise_variance = 1e-2;  ///< σ_n² > 0
};
absl::Status Validate(const SeArdKernel& kernel, int dimension);

// Scratch for GpModel::Linearise, owned by the caller so that a shared model stays
// const and thread-safe while repeated calls reuse their memory.
struct LinearisationScratch {
  Eigen::MatrixXd cross, projection;
};

// The linGP at one point: m̂ (size d+1) and V̂ ((d+1)×(d+1), symmetric PSD).
struct LinGp {
  Eigen::VectorXd mean;        ///< m̂ = [μ(x); ∇μ(x)]
  Eigen::MatrixXd covariance;  ///< V̂; V̂(0,0) = σ²(x), the exact predictive variance
  double Mean(const Eigen::VectorXd& delta) const;      ///< m̂ᵀ[1; Δ]
  double Variance(const Eigen::VectorXd& delta) const;  ///< [1; Δ]ᵀ V̂ [1; Δ]
};

class GpModel {
 public:
  // inputs: N×d (one training regressor per row), targets: N. INVALID_ARGUMENT naming the
  // field for bad sizes or values; FAILED_PRECONDITION when K + σ_n² I is not positive
  // definite in floating point.
  static absl::StatusOr<GpModel> Create(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel);

  // Eigenvalues of K below this fraction of σ_n² are treated as 0 by Linearise().
  static constexpr double kDroppedEigenvalue = 1e-10;

  int num_points() const { return static_cast<int>(inputs_.rows()); }
  int basis_rank() const { return static_cast<int>(basis_.cols()); }
  int dimension() const { return static_cast<int>(inputs_.cols()); }
  const SeArdKernel& kernel() const { return kernel_; }
  const Eigen::MatrixXd& inputs() const { return inputs_; }
  const Eigen::VectorXd& targets() const { return targets_; }

  // Predictive mean μ(x) (O(N d)).
  double Mean(const Eigen::VectorXd& x) const;
  // μ(x) and ∇μ(x) (O(N d)).
  double MeanAndGradient(const Eigen::VectorXd& x, Eigen::VectorXd* gradient) const;
  // Predictive mean and variance of f(x) (O(N² ) for the variance).
  void Predict(const Eigen::VectorXd& x, double* mean, double* variance) const;
  // The linGP at each row of `points` (P×d), batched over P·(d+1) cross-covariance
  // columns W. The data term Wᵀ(K + σ_n² I)⁻¹W uses the eigendecomposition of K computed
  // in Create(): K of a smooth kernel on low-dimensional regressors has numerically low
  // rank r (about 70 at N = 1500 on the tanh example), so with W = U_r A + W⊥,
  //   Wᵀ(K + σ_n² I)⁻¹W = Aᵀ(S_r + σ_n² I)⁻¹A + W⊥ᵀW⊥ / σ_n²,
  // exact except that the dropped eigenvalues (≤ kDroppedEigenvalue·σ_n², at rounding
  // level) count as 0: an error of at most that factor times the W⊥ term. O(N r) per
  // column instead of O(N²). `out` is resized to P.
  void Linearise(const Eigen::MatrixXd& points, std::vector<LinGp>* out, LinearisationScratch* scratch) const;
  void Linearise(const Eigen::MatrixXd& points, std::vector<LinGp>* out) const {
    LinearisationScratch scratch;
    Linearise(points, out, &scratch);
  }
  LinGp Linearise(const Eigen::VectorXd& x) const;

 private:
  GpModel(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel);
  // Kernel values are computed in blocks of training points held on the stack, so that the
  // squared distances and exp() run vectorised and nothing is allocated (Mean() runs once
  // per horizon step per SCP iteration).
  static constexpr int kBlock = 64;
  using KernelBlock = Eigen::Array<double, kBlock, 1>;
  // k(X_j, x) for j = first..first+count-1 (count ≤ kBlock) into the head of *k.
  void KernelValues(int first, int count, const Eigen::VectorXd& x, KernelBlock* k) const;
  // Column j of `w` gets [k(X, x), ∂k(X, x)/∂x_1, ..., ∂k(X, x)/∂x_d] for x = `x`,
  // starting at column `first`.
  void CrossCovariances(const Eigen::VectorXd& x, Eigen::MatrixXd* w, int first) const;

  Eigen::MatrixXd inputs_;
  Eigen::VectorXd targets_;
  SeArdKernel kernel_;
  Eigen::VectorXd inverse_squared_lengths_;  ///< 1/ℓ_i²
  Eigen::LLT<Eigen::MatrixXd> cholesky_;     ///< of K + σ_n² I (mean weights, Predict)
  Eigen::VectorXd alpha_;                    ///< (K + σ_n² I)⁻¹ Y
  Eigen::MatrixXd basis_;                    ///< U_r: K's eigenvectors with eigenvalue > the cut
  Eigen::VectorXd basis_weights_;            ///< 1/(s_i + σ_n²) for those

};

// The covariance matrix K(X, X) (without noise) of a kernel on the rows of `inputs`.
Eigen::MatrixXd KernelMatrix(const SeArdKernel& kernel, const Eigen::MatrixXd& inputs);

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_GP_MODEL_H_
