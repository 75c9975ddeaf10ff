#include "core/gp/gp_model.h"

#include <cmath>

#include "Eigen/Eigenvalues"

#include "absl/strings/str_cat.h"

namespace nupmpc::gp {

absl::Status Validate(const SeArdKernel& kernel, int dimension) {
  if (!(kernel.signal_variance > 0.0) || !std::isfinite(kernel.signal_variance)) {
    return absl::InvalidArgumentError(
        absl::StrCat("kernel.signal_variance: must be finite and > 0, got ", kernel.signal_variance));
  }
  if (!(kernel.noise_variance > 0.0) || !std::isfinite(kernel.noise_variance)) {
    return absl::InvalidArgumentError(
        absl::StrCat("kernel.noise_variance: must be finite and > 0, got ", kernel.noise_variance));
  }
  if (kernel.length_scales.size() != dimension) {
    return absl::InvalidArgumentError(absl::StrCat("kernel.length_scales: expected ", dimension,
                                                   " values (one per regressor), got ", kernel.length_scales.size()));
  }
  for (int i = 0; i < dimension; ++i) {
    if (!(kernel.length_scales(i) > 0.0) || !std::isfinite(kernel.length_scales(i))) {
      return absl::InvalidArgumentError(
          absl::StrCat("kernel.length_scales[", i, "]: must be finite and > 0, got ", kernel.length_scales(i)));
    }
  }
  return absl::OkStatus();
}

double LinGp::Mean(const Eigen::VectorXd& delta) const {
  return mean(0) + mean.tail(mean.size() - 1).dot(delta);
}

double LinGp::Variance(const Eigen::VectorXd& delta) const {
  const Eigen::Index d = delta.size();
  return covariance(0, 0) + 2.0 * covariance.col(0).tail(d).dot(delta) +
         delta.dot(covariance.bottomRightCorner(d, d) * delta);
}

Eigen::MatrixXd KernelMatrix(const SeArdKernel& kernel, const Eigen::MatrixXd& inputs) {
  const Eigen::Index n = inputs.rows();
  const Eigen::RowVectorXd scale = kernel.length_scales.cwiseInverse().transpose();
  const Eigen::MatrixXd scaled = inputs.array().rowwise() * scale.array();
  const Eigen::VectorXd norms = scaled.rowwise().squaredNorm();
  Eigen::MatrixXd k = scaled * scaled.transpose();  // r² = |a|² + |b|² - 2 a·b
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = 0; i < n; ++i) {
      const double r2 = std::max(0.0, norms(i) + norms(j) - 2.0 * k(i, j));
      k(i, j) = kernel.signal_variance * std::exp(-0.5 * r2);
    }
    k(j, j) = kernel.signal_variance;
  }
  return k;
}

GpModel::GpModel(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel)
    : inputs_(std::move(inputs)), targets_(std::move(targets)), kernel_(std::move(kernel)) {
  inverse_squared_lengths_ = kernel_.length_scales.array().square().inverse().matrix();
}

absl::StatusOr<GpModel> GpModel::Create(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel) {
  if (inputs.rows() < 1 || inputs.cols() < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("inputs: need at least one point of dimension ≥ 1, got ", inputs.rows(), "x", inputs.cols()));
  }
  if (targets.size() != inputs.rows()) {
    return absl::InvalidArgumentError(
        absl::StrCat("targets: expected ", inputs.rows(), " values (one per input row), got ", targets.size()));
  }
  if (!inputs.allFinite()) return absl::InvalidArgumentError("inputs: contains a non-finite number");
  if (!targets.allFinite()) return absl::InvalidArgumentError("targets: contains a non-finite number");
  if (absl::Status valid = Validate(kernel, static_cast<int>(inputs.cols())); !valid.ok()) return valid;

  GpModel model(std::move(inputs), std::move(targets), std::move(kernel));
  Eigen::MatrixXd k = KernelMatrix(model.kernel_, model.inputs_);
  {
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(k);
    if (eigen.info() != Eigen::Success) return absl::InternalError("eigendecomposition of K failed");
    const double cut = kDroppedEigenvalue * model.kernel_.noise_variance;
    const Eigen::VectorXd& s = eigen.eigenvalues();  // ascending
    Eigen::Index kept = 0;
    while (kept < s.size() && s(s.size() - 1 - kept) > cut) ++kept;
    model.basis_ = eigen.eigenvectors().rightCols(kept);
    model.basis_weights_ = (s.tail(kept).array() + model.kernel_.noise_variance).inverse().matrix();
  }
  k.diagonal().array() += model.kernel_.noise_variance;
  model.cholesky_.compute(k);
  if (model.cholesky_.info() != Eigen::Success) {
    return absl::FailedPreconditionError("K + noise_variance·I is not positive definite (raise noise_variance)");
  }
  model.alpha_ = model.cholesky_.solve(model.targets_);
  return model;
}

double GpModel::KernelToPoint(int j, const Eigen::VectorXd& x) const {
  double r2 = 0.0;
  for (int i = 0; i < dimension(); ++i) {
    const double diff = x(i) - inputs_(j, i);
    r2 += diff * diff * inverse_squared_lengths_(i);
  }
  return kernel_.signal_variance * std::exp(-0.5 * r2);
}

double GpModel::Mean(const Eigen::VectorXd& x) const {
  double mean = 0.0;
  for (int j = 0; j < num_points(); ++j) mean += alpha_(j) * KernelToPoint(j, x);
  return mean;
}

double GpModel::MeanAndGradient(const Eigen::VectorXd& x, Eigen::VectorXd* gradient) const {
  const int d = dimension();
  gradient->setZero(d);
  double mean = 0.0;
  for (int j = 0; j < num_points(); ++j) {
    const double weighted = alpha_(j) * KernelToPoint(j, x);
    mean += weighted;
    for (int i = 0; i < d; ++i) (*gradient)(i) -= weighted * (x(i) - inputs_(j, i)) * inverse_squared_lengths_(i);
  }
  return mean;
}

void GpModel::CrossCovariances(const Eigen::VectorXd& x, Eigen::MatrixXd* w, int first) const {
  const int d = dimension();
  for (int j = 0; j < num_points(); ++j) {
    const double k = KernelToPoint(j, x);
    (*w)(j, first) = k;
    // ∂k(X_j, x)/∂x_i = -k (x_i - X_ji)/ℓ_i²
    for (int i = 0; i < d; ++i) (*w)(j, first + 1 + i) = -k * (x(i) - inputs_(j, i)) * inverse_squared_lengths_(i);
  }
}

void GpModel::Predict(const Eigen::VectorXd& x, double* mean, double* variance) const {
  Eigen::MatrixXd w(num_points(), dimension() + 1);
  CrossCovariances(x, &w, 0);
  *mean = w.col(0).dot(alpha_);
  const Eigen::VectorXd z = cholesky_.matrixL().solve(w.col(0));
  *variance = std::max(0.0, kernel_.signal_variance - z.squaredNorm());
}

void GpModel::Linearise(const Eigen::MatrixXd& points, std::vector<LinGp>* out,
                        LinearisationScratch* scratch) const {
  const int d = dimension(), P = static_cast<int>(points.rows()), c = d + 1;
  Eigen::MatrixXd& w = scratch->cross;
  Eigen::MatrixXd& projection = scratch->projection;
  w.resize(num_points(), P * c);
  for (int p = 0; p < P; ++p) CrossCovariances(points.row(p).transpose(), &w, p * c);
  const Eigen::VectorXd means = w.transpose() * alpha_;  // [μ; ∇μ] per point, stacked
  projection.noalias() = basis_.transpose() * w;        // A = U_rᵀ W
  w.noalias() -= basis_ * projection;                   // W⊥ = W - U_r A
  const double inverse_noise = 1.0 / kernel_.noise_variance;
  out->resize(P);
  for (int p = 0; p < P; ++p) {
    LinGp& lin = (*out)[p];
    lin.mean = means.segment(p * c, c);
    const auto a = projection.middleCols(p * c, c);
    const auto residual = w.middleCols(p * c, c);
    lin.covariance.noalias() = -(a.transpose() * basis_weights_.asDiagonal() * a);
    lin.covariance.noalias() -= inverse_noise * (residual.transpose() * residual);
    // Prior covariance of [f; ∇f] at one point: diag(σ_f², σ_f²/ℓ²) (k and ∇k are
    // uncorrelated at coincident points); minus what the data explain.
    lin.covariance(0, 0) += kernel_.signal_variance;
    for (int i = 0; i < d; ++i) lin.covariance(1 + i, 1 + i) += kernel_.signal_variance * inverse_squared_lengths_(i);
    lin.covariance(0, 0) = std::max(lin.covariance(0, 0), 0.0);
  }
}

LinGp GpModel::Linearise(const Eigen::VectorXd& x) const {
  std::vector<LinGp> out;
  Linearise(x.transpose(), &out);
  return out[0];
}

}  // namespace nupmpc::gp
