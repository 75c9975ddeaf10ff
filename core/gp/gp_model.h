#ifndef NUPMPC_CORE_GP_GP_MODEL_H_
#define NUPMPC_CORE_GP_GP_MODEL_H_

// Gaussian-process regression with a squared-exponential ARD kernel and zero prior mean
// (Rasmussen & Williams ch. 2; [Nghiem] §II):
//
//   k(x, x') = σ_f² exp(-½ Σ_i (x_i - x'_i)² / ℓ_i²),   y = f(x) + ε,  ε ~ N(0, σ_n²)
//
// The Cholesky factor of K + σ_n² I and α = (K + σ_n² I)⁻¹ Y are computed once per model
// (Create, stoppable by a deadline or cancel flag: core/public/deadline.h) and reused by every
// prediction. Predictions are of the latent f (no noise
// term), as in [Nghiem] (1).
//
// The linGP ([Nghiem] (3)–(6)): at a point x, f̂ = [f(x); ∇f(x)] is Gaussian with mean
// m̂ and covariance V̂; the linearised process f(x + Δ) ≈ [1; Δ]ᵀ f̂ has mean m̂ᵀ[1; Δ]
// (the exact mean's first-order Taylor expansion: the mean of the gradient is the
// gradient of the mean) and variance [1; Δ]ᵀ V̂ [1; Δ], convex in Δ.

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/public/deadline.h"

namespace nupmpc::gp {

struct SeArdKernel {
  double signal_variance = 1.0;   ///< σ_f² > 0
  Eigen::VectorXd length_scales;  ///< ℓ_i > 0, one per regressor
  double noise_variance = 1e-2;   ///< σ_n² > 0
};
absl::Status Validate(const SeArdKernel& kernel, int dimension);

// Scratch for GpModel::Linearise, owned by the caller so that a shared model stays
// const and thread-safe while repeated calls reuse their memory.
struct LinearisationScratch {
  Eigen::MatrixXd cross, projection;
  Eigen::MatrixXd pivot_cross;     ///< the fast path's [k, ∇k](Z, x) columns, then Φ: m × (d+1)
  Eigen::MatrixXd pivot_weighted;  ///< M Φ
  Eigen::VectorXd means;           ///< [μ; ∇μ] of the O(N r) path's points, stacked
  std::vector<int> full_path;      ///< the points that need the O(N r) path
};

// The linGP at one point: m̂ (size d+1) and V̂ ((d+1)×(d+1), symmetric PSD).
struct LinGp {
  Eigen::VectorXd mean;                                 ///< m̂ = [μ(x); ∇μ(x)]
  Eigen::MatrixXd covariance;                           ///< V̂; V̂(0,0) = σ²(x), the exact predictive variance
  double Mean(const Eigen::VectorXd& delta) const;      ///< m̂ᵀ[1; Δ]
  double Variance(const Eigen::VectorXd& delta) const;  ///< [1; Δ]ᵀ V̂ [1; Δ]
};

class GpModel {
 public:
  // inputs: N×d (one training regressor per row), targets: N. INVALID_ARGUMENT naming the
  // field for bad sizes or values; FAILED_PRECONDITION when K + σ_n² I is not positive
  // definite in floating point; DEADLINE_EXCEEDED / CANCELLED when `stop` fires, saying in
  // which step (each O(N²) or O(N³) step is checked in blocks: core/gp/blocked_cholesky.h).
  static absl::StatusOr<GpModel> Create(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel,
                                        const core::Deadline& stop = {});

  // The low-rank factor K ≈ L Lᵀ stops when every diagonal entry of what it leaves out,
  // K - L Lᵀ (PSD), is below this fraction of σ_n² (Linearise() says what that bounds).
  static constexpr double kDroppedEigenvalue = 1e-10;
  // Largest power p(x) / prior variance of a column for which Linearise() takes the fast
  // path (tested against a dense linGP to 1e-9, inside and outside the training data).
  static constexpr double kFastPathPower = 1e-8;

  int num_points() const { return static_cast<int>(inputs_.rows()); }
  int basis_rank() const { return static_cast<int>(basis_.cols()); }
  // Training points Z of the pivoted low-rank factor behind Linearise()'s fast path (0: none).
  int num_pivots() const { return static_cast<int>(pivot_inputs_.rows()); }
  int dimension() const { return static_cast<int>(inputs_.cols()); }
  const SeArdKernel& kernel() const { return kernel_; }
  const Eigen::MatrixXd& inputs() const { return inputs_; }
  const Eigen::VectorXd& targets() const { return targets_; }

  // Predictive mean μ(x): k(Z, x)ᵀ L_Z⁻ᵀ Lᵀα in O(m²) where the power check of Linearise()
  // passes, else O(N d).
  double Mean(const Eigen::VectorXd& x) const;
  // μ(x) and ∇μ(x) (O(N d)).
  double MeanAndGradient(const Eigen::VectorXd& x, Eigen::VectorXd* gradient) const;
  // Predictive mean and variance of f(x) (O(N² ) for the variance).
  void Predict(const Eigen::VectorXd& x, double* mean, double* variance) const;
  // The linGP at each row of `points` (P×d), batched over P·(d+1) cross-covariance
  // columns W. The data term Wᵀ(K + σ_n² I)⁻¹W uses the pivoted low-rank factor
  // K ≈ L Lᵀ (N × r) computed in Create(): K of a smooth kernel on low-dimensional
  // regressors has numerically low rank r. With Q an orthonormal basis of L's columns,
  // R = QᵀL and W = Q A + W⊥ (A = QᵀW),
  //   Wᵀ(L Lᵀ + σ_n² I)⁻¹W = Aᵀ(R Rᵀ + σ_n² I)⁻¹A + W⊥ᵀW⊥ / σ_n²,
  // exact for K except for what L leaves out: K - L Lᵀ is PSD with every diagonal entry
  // ≤ kDroppedEigenvalue·σ_n² (at rounding level), so its norm is at most N times that, a
  // relative error of at most N·kDroppedEigenvalue in the data term. O(N r) per column
  // instead of O(N²). When no such factor of rank ≤ kMaxPivots (and ≤ N/4) exists, the exact
  // O(N²) path through the Cholesky factor runs instead (basis_rank() = 0). No
  // eigendecomposition of K: it is O(N³) with a large constant and cannot be interrupted.
  //
  // Fast path, O(m²) per column and independent of N: a pivoted Cholesky factor
  // K ≈ L Lᵀ on m pivot points Z (residual diagonal ≤ kDroppedEigenvalue·σ_n², so m ≈ r)
  // reproduces every kernel function k(X, x) whose own residual ("power") at x is small:
  // |k(X_j, x) - (L φ(x))_j| ≤ √(R_jj · p(x)), φ(x) = L_Z⁻¹ k(Z, x),
  // p(x) = k(x, x) - |φ(x)|² (and the same for the gradient columns). Where every column's
  // power is below kFastPathPower of its prior variance (x inside the training data), the
  // linGP is m̂ = Φᵀ Lᵀα and V̂ = prior - Φᵀ M Φ with M = Lᵀ(L Lᵀ + σ_n² I)⁻¹ L; elsewhere
  // the O(N r) path runs. `out` is resized to P. Returns how many points took the fast path.
  int Linearise(const Eigen::MatrixXd& points, std::vector<LinGp>* out, LinearisationScratch* scratch) const;
  int Linearise(const Eigen::MatrixXd& points, std::vector<LinGp>* out) const {
    LinearisationScratch scratch;
    return Linearise(points, out, &scratch);
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
  // k(Z, x) into the m values of `k`.
  void PivotKernelValues(const Eigen::VectorXd& x, Eigen::Ref<Eigen::VectorXd> k) const;
  // [k, ∇k](Z, x) against the pivot points Z into the m × (d+1) matrix *g.
  void PivotCrossCovariances(const Eigen::VectorXd& x, Eigen::MatrixXd* g) const;
  // The fast path's power check for one column: its prior variance minus the part the
  // pivots capture (|Φ_i|²) is at most kFastPathPower of the prior.
  static bool WellReproduced(double prior, double captured) { return prior - captured <= kFastPathPower * prior; }
  // The pivoted factor of K (Create()): sets Z, L_Z, M, the basis Q and the factor of
  // R Rᵀ + σ_n² I and returns L (N × m), or leaves no low-rank path and returns an empty
  // matrix when it needs more than min(kMaxPivots, kMaxPivotFraction·N) pivots (then the
  // exact Cholesky path is about as cheap).
  absl::StatusOr<Eigen::MatrixXd> FactorPivots(const Eigen::MatrixXd& k, const core::Deadline& stop);
  // Q, an orthonormal basis of the columns of `l` (block Gram-Schmidt, twice), and the
  // Cholesky factor of R Rᵀ + σ_n² I, R = Qᵀ l.
  absl::Status FactorBasis(const Eigen::MatrixXd& l, const core::Deadline& stop);
  // The fast path at one point; false (nothing written) when a column's power is too large.
  bool LineariseFromPivots(const Eigen::VectorXd& x, LinGp* lin, LinearisationScratch* scratch) const;
  static constexpr double kMaxPivotFraction = 0.25;
  static constexpr int kMaxPivots = 512;  ///< so that Mean()'s pivot vector lives on the stack
  using PivotVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxPivots, 1>;

  Eigen::MatrixXd inputs_;
  Eigen::VectorXd targets_;
  SeArdKernel kernel_;
  Eigen::VectorXd inverse_squared_lengths_;  ///< 1/ℓ_i²
  Eigen::MatrixXd factor_;                   ///< lower Cholesky factor of K + σ_n² I (upper: unused)
  Eigen::VectorXd alpha_;                    ///< (K + σ_n² I)⁻¹ Y
  Eigen::MatrixXd basis_;                    ///< Q: orthonormal basis of the low-rank factor's columns
  Eigen::MatrixXd basis_factor_;             ///< lower Cholesky factor of R Rᵀ + σ_n² I
  Eigen::MatrixXd pivot_inputs_;             ///< Z: m × d
  Eigen::MatrixXd pivot_factor_;             ///< L_Z: the factor's rows at Z, lower triangular m × m
  Eigen::VectorXd pivot_mean_weights_;       ///< Lᵀ α
  Eigen::MatrixXd pivot_data_term_;  ///< M = Lᵀ (L Lᵀ + σ_n² I)⁻¹ L = I - σ_n² (LᵀL + σ_n² I)⁻¹
};

// The covariance matrix K(X, X) (without noise) of a kernel on the rows of `inputs`.
Eigen::MatrixXd KernelMatrix(const SeArdKernel& kernel, const Eigen::MatrixXd& inputs);
// The same into *k (resized only if its size differs), a block of columns per interrupt
// check; `scaled` is scratch (N × d, same rule).
absl::Status FillKernelMatrix(const SeArdKernel& kernel, const Eigen::MatrixXd& inputs, const core::Deadline& stop,
                              Eigen::MatrixXd* k, Eigen::MatrixXd* scaled);

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_GP_MODEL_H_
