#include "core/gp/gp_model.h"

#include <algorithm>
#include <cmath>

#include "Eigen/Cholesky"
#include "absl/strings/str_cat.h"
#include "core/gp/blocked_cholesky.h"
#include "core/util/status_macros.h"

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

double LinGp::Mean(const Eigen::VectorXd& delta) const { return mean(0) + mean.tail(mean.size() - 1).dot(delta); }

double LinGp::Variance(const Eigen::VectorXd& delta) const {
  const Eigen::Index d = delta.size();
  return covariance(0, 0) + 2.0 * covariance.col(0).tail(d).dot(delta) +
         delta.dot(covariance.bottomRightCorner(d, d) * delta);
}

Eigen::MatrixXd KernelMatrix(const SeArdKernel& kernel, const Eigen::MatrixXd& inputs) {
  Eigen::MatrixXd k, scaled;
  FillKernelMatrix(kernel, inputs, core::Deadline{}, &k, &scaled).IgnoreError();  // no interrupt: cannot fail
  return k;
}

absl::Status FillKernelMatrix(const SeArdKernel& kernel, const Eigen::MatrixXd& inputs, const core::Deadline& stop,
                              Eigen::MatrixXd* k, Eigen::MatrixXd* scaled) {
  const Eigen::Index n = inputs.rows(), d = inputs.cols();
  if (k->rows() != n || k->cols() != n) k->resize(n, n);
  // The scaled regressors x_i/ℓ_i, and in the last column their squared norms.
  if (scaled->rows() != n || scaled->cols() != d + 1) scaled->resize(n, d + 1);
  for (Eigen::Index i = 0; i < d; ++i) scaled->col(i) = inputs.col(i) / kernel.length_scales(i);
  scaled->col(d) = scaled->leftCols(d).rowwise().squaredNorm();
  const auto points = scaled->leftCols(d);
  const auto norms = scaled->col(d).array();
  // A block of columns per check: r² = |a|² + |b|² - 2 a·b, then σ_f² exp(-r²/2).
  constexpr Eigen::Index kColumns = 256;
  for (Eigen::Index j0 = 0; j0 < n; j0 += kColumns) {
    if (stop.Requested()) {
      return stop.Stopped(absl::StrCat("building the kernel matrix (column ", j0, " of ", n, ")"));
    }
    const Eigen::Index w = std::min(kColumns, n - j0);
    auto block = k->middleCols(j0, w);
    block.noalias() = points * points.middleRows(j0, w).transpose();
    for (Eigen::Index j = 0; j < w; ++j) {
      block.col(j) = kernel.signal_variance *
                     (-0.5 * (norms + norms(j0 + j) - 2.0 * block.col(j).array()).max(0.0)).exp().matrix();
      block(j0 + j, j) = kernel.signal_variance;
    }
  }
  return absl::OkStatus();
}

GpModel::GpModel(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel)
    : inputs_(std::move(inputs)), targets_(std::move(targets)), kernel_(std::move(kernel)) {
  inverse_squared_lengths_ = kernel_.length_scales.array().square().inverse().matrix();
}

absl::StatusOr<GpModel> GpModel::Create(Eigen::MatrixXd inputs, Eigen::VectorXd targets, SeArdKernel kernel,
                                        const core::Deadline& stop) {
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
  // Three steps, each checking `stop` between blocks; a stopped set-up says which.
  const auto stopped = [&](int step, const absl::Status& status) {
    return absl::Status(status.code(), absl::StrCat("GP set-up stopped in step ", step,
                                                    " of 3 (kernel matrix, low-rank factor, Cholesky factor) on ",
                                                    model.num_points(), " points: ", status.message()));
  };
  Eigen::MatrixXd k, scaled;
  if (absl::Status s = FillKernelMatrix(model.kernel_, model.inputs_, stop, &k, &scaled); !s.ok()) {
    return stopped(1, s);
  }
  absl::StatusOr<Eigen::MatrixXd> pivot_columns = model.FactorPivots(k, stop);
  if (!pivot_columns.ok()) return stopped(2, pivot_columns.status());
  k.diagonal().array() += model.kernel_.noise_variance;
  if (absl::Status s = BlockedCholesky(k, stop, "K + σ_n² I"); !s.ok()) {
    if (s.code() == absl::StatusCode::kFailedPrecondition) {
      return absl::FailedPreconditionError("K + noise_variance·I is not positive definite (raise noise_variance)");
    }
    return stopped(3, s);
  }
  model.factor_ = std::move(k);
  auto l = model.factor_.triangularView<Eigen::Lower>();
  model.alpha_ = l.solve(model.targets_);
  l.transpose().solveInPlace(model.alpha_);
  if (model.num_pivots() > 0) model.pivot_mean_weights_ = pivot_columns->transpose() * model.alpha_;
  return model;
}

absl::StatusOr<Eigen::MatrixXd> GpModel::FactorPivots(const Eigen::MatrixXd& k, const core::Deadline& stop) {
  // Greedy pivoted Cholesky (the largest residual diagonal first) until every residual
  // diagonal is at the eigenvalue cut. O(N m) per pivot, checked per pivot.
  const int n = num_points(), max_pivots = std::min(kMaxPivots, static_cast<int>(kMaxPivotFraction * n));
  const double cut = kDroppedEigenvalue * kernel_.noise_variance;
  Eigen::VectorXd residual = k.diagonal();
  Eigen::MatrixXd factor(n, std::max(max_pivots, 1));
  std::vector<int> pivots;
  for (int j = 0;; ++j) {
    Eigen::Index p = 0;
    if (residual.maxCoeff(&p) <= cut) break;
    if (j == max_pivots) return Eigen::MatrixXd();  // not low-rank enough to pay off: the exact path
    if (stop.Requested()) return stop.Stopped(absl::StrCat("computing the low-rank factor of K (pivot ", j, ")"));
    factor.col(j) = k.col(p) - factor.leftCols(j) * factor.row(p).head(j).transpose();
    factor.col(j) /= std::sqrt(residual(p));
    residual -= factor.col(j).cwiseAbs2();
    residual(p) = 0.0;  // exactly reproduced from now on
    pivots.push_back(static_cast<int>(p));
  }
  const int m = static_cast<int>(pivots.size());
  Eigen::MatrixXd l = factor.leftCols(m);
  pivot_inputs_.resize(m, dimension());
  pivot_factor_.resize(m, m);
  for (int i = 0; i < m; ++i) {
    pivot_inputs_.row(i) = inputs_.row(pivots[i]);
    pivot_factor_.row(i) = l.row(pivots[i]);
  }
  pivot_factor_ = pivot_factor_.triangularView<Eigen::Lower>();  // above: rounding noise of exact zeros
  // LᵀL + σ_n² I by column strips: O(N m²) in all, checked per strip.
  constexpr int kColumns = 16;
  Eigen::MatrixXd gram(m, m);
  for (int j0 = 0; j0 < m; j0 += kColumns) {
    if (stop.Requested()) {
      return stop.Stopped(absl::StrCat("computing the low-rank factor's Gram matrix (column ", j0, " of ", m, ")"));
    }
    const int w = std::min(kColumns, m - j0);
    gram.middleCols(j0, w).noalias() = l.transpose() * l.middleCols(j0, w);
  }
  gram.diagonal().array() += kernel_.noise_variance;
  pivot_data_term_ = -kernel_.noise_variance * gram.llt().solve(Eigen::MatrixXd::Identity(m, m));
  pivot_data_term_.diagonal().array() += 1.0;
  NUPMPC_RETURN_IF_ERROR(FactorBasis(l, stop));
  return l;
}

absl::Status GpModel::FactorBasis(const Eigen::MatrixXd& l, const core::Deadline& stop) {
  const Eigen::Index m = l.cols();
  constexpr Eigen::Index kColumns = 16;  // per check: O(N m kColumns)
  const auto where = [&](Eigen::Index column) {
    return absl::StrCat("orthonormalising the low-rank factor (column ", column, " of ", m, ")");
  };
  basis_ = l;
  Eigen::MatrixXd coefficients(m, kColumns);
  for (Eigen::Index j0 = 0; j0 < m; j0 += kColumns) {
    const Eigen::Index w = std::min(kColumns, m - j0);
    auto block = basis_.middleCols(j0, w);
    // Twice (classical Gram-Schmidt against the earlier blocks, modified within the block):
    // one pass leaves errors of order ε·cond(L), and L's columns decay to the cut.
    for (int pass = 0; pass < 2; ++pass) {
      if (stop.Requested()) return stop.Stopped(where(j0));
      if (j0 > 0) {
        auto c = coefficients.topLeftCorner(j0, w);
        c.noalias() = basis_.leftCols(j0).transpose() * block;
        block.noalias() -= basis_.leftCols(j0) * c;
      }
      for (Eigen::Index c = 0; c < w; ++c) {
        for (Eigen::Index b = 0; b < c; ++b) block.col(c) -= block.col(b).dot(block.col(c)) * block.col(b);
        const double norm = block.col(c).norm();
        if (norm > 0.0) {
          block.col(c) /= norm;
        } else {
          block.col(c).setZero();  // exactly dependent: contributes nothing
        }
      }
    }
  }
  // R = Qᵀ L by column strips, then the factor of R Rᵀ + σ_n² I (m × m, eigenvalues ≥ σ_n²).
  Eigen::MatrixXd r(m, m);
  for (Eigen::Index j0 = 0; j0 < m; j0 += kColumns) {
    if (stop.Requested()) return stop.Stopped(where(m));
    const Eigen::Index w = std::min(kColumns, m - j0);
    r.middleCols(j0, w).noalias() = basis_.transpose() * l.middleCols(j0, w);
  }
  basis_factor_.noalias() = r * r.transpose();
  basis_factor_.diagonal().array() += kernel_.noise_variance;
  Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(basis_factor_);  // in place
  if (llt.info() != Eigen::Success) return absl::InternalError("R Rᵀ + σ_n² I is not positive definite");
  basis_factor_ = basis_factor_.triangularView<Eigen::Lower>();
  return absl::OkStatus();
}

void GpModel::KernelValues(int first, int count, const Eigen::VectorXd& x, KernelBlock* k) const {
  auto values = k->head(count);
  values.setZero();  // the scaled squared distance first
  for (int i = 0; i < dimension(); ++i) {
    values += (inputs_.col(i).segment(first, count).array() - x(i)).square() * inverse_squared_lengths_(i);
  }
  values = kernel_.signal_variance * (-0.5 * values).exp();
}

double GpModel::Mean(const Eigen::VectorXd& x) const {
  if (num_pivots() > 0) {
    PivotVector phi(num_pivots());
    PivotKernelValues(x, phi);
    pivot_factor_.triangularView<Eigen::Lower>().solveInPlace(phi);  // φ = L_Z⁻¹ k(Z, x)
    if (WellReproduced(kernel_.signal_variance, phi.squaredNorm())) return phi.dot(pivot_mean_weights_);
  }
  KernelBlock k;
  double mean = 0.0;
  for (int first = 0; first < num_points(); first += kBlock) {
    const int count = std::min(kBlock, num_points() - first);
    KernelValues(first, count, x, &k);
    mean += (alpha_.segment(first, count).array() * k.head(count)).sum();
  }
  return mean;
}

double GpModel::MeanAndGradient(const Eigen::VectorXd& x, Eigen::VectorXd* gradient) const {
  const int d = dimension();
  gradient->setZero(d);
  KernelBlock k;
  double mean = 0.0;
  for (int first = 0; first < num_points(); first += kBlock) {
    const int count = std::min(kBlock, num_points() - first);
    KernelValues(first, count, x, &k);
    auto weighted = k.head(count);
    weighted *= alpha_.segment(first, count).array();
    mean += weighted.sum();
    // ∂k(X_j, x)/∂x_i = -k (x_i - X_ji)/ℓ_i²
    for (int i = 0; i < d; ++i) {
      (*gradient)(i) -=
          (weighted * (x(i) - inputs_.col(i).segment(first, count).array())).sum() * inverse_squared_lengths_(i);
    }
  }
  return mean;
}

void GpModel::CrossCovariances(const Eigen::VectorXd& x, Eigen::MatrixXd* w, int first_column) const {
  const int d = dimension();
  KernelBlock k;
  for (int first = 0; first < num_points(); first += kBlock) {
    const int count = std::min(kBlock, num_points() - first);
    KernelValues(first, count, x, &k);
    w->col(first_column).segment(first, count) = k.head(count).matrix();
    // ∂k(X_j, x)/∂x_i = -k (x_i - X_ji)/ℓ_i²
    for (int i = 0; i < d; ++i) {
      w->col(first_column + 1 + i).segment(first, count) =
          (-inverse_squared_lengths_(i) * k.head(count) * (x(i) - inputs_.col(i).segment(first, count).array()))
              .matrix();
    }
  }
}

void GpModel::PivotKernelValues(const Eigen::VectorXd& x, Eigen::Ref<Eigen::VectorXd> k) const {
  k.setZero();  // the scaled squared distances first
  for (int i = 0; i < dimension(); ++i) {
    k.array() += (pivot_inputs_.col(i).array() - x(i)).square() * inverse_squared_lengths_(i);
  }
  k = (kernel_.signal_variance * (-0.5 * k.array()).exp()).matrix();
}

void GpModel::PivotCrossCovariances(const Eigen::VectorXd& x, Eigen::MatrixXd* g) const {
  const int d = dimension();
  g->resize(num_pivots(), d + 1);
  PivotKernelValues(x, g->col(0));
  for (int i = 0; i < d; ++i) {
    g->col(1 + i) = (-inverse_squared_lengths_(i) * g->col(0).array() * (x(i) - pivot_inputs_.col(i).array())).matrix();
  }
}

bool GpModel::LineariseFromPivots(const Eigen::VectorXd& x, LinGp* lin, LinearisationScratch* scratch) const {
  const int d = dimension(), c = d + 1;
  Eigen::MatrixXd* g = &scratch->pivot_cross;
  PivotCrossCovariances(x, g);
  pivot_factor_.triangularView<Eigen::Lower>().solveInPlace(*g);  // Φ = L_Z⁻¹ G
  for (int i = 0; i < c; ++i) {
    const double prior = i == 0 ? kernel_.signal_variance : kernel_.signal_variance * inverse_squared_lengths_(i - 1);
    if (!WellReproduced(prior, g->col(i).squaredNorm())) return false;
  }
  lin->mean.resize(c);
  lin->mean.noalias() = g->transpose() * pivot_mean_weights_;
  scratch->pivot_weighted.resize(g->rows(), c);
  scratch->pivot_weighted.noalias() = pivot_data_term_ * *g;
  lin->covariance.resize(c, c);
  lin->covariance.noalias() = -(g->transpose() * scratch->pivot_weighted);
  lin->covariance(0, 0) += kernel_.signal_variance;
  for (int i = 0; i < d; ++i) lin->covariance(1 + i, 1 + i) += kernel_.signal_variance * inverse_squared_lengths_(i);
  lin->covariance(0, 0) = std::max(lin->covariance(0, 0), 0.0);
  return true;
}

void GpModel::Predict(const Eigen::VectorXd& x, double* mean, double* variance) const {
  Eigen::MatrixXd w(num_points(), dimension() + 1);
  CrossCovariances(x, &w, 0);
  *mean = w.col(0).dot(alpha_);
  const Eigen::VectorXd z = factor_.triangularView<Eigen::Lower>().solve(w.col(0));
  *variance = std::max(0.0, kernel_.signal_variance - z.squaredNorm());
}

int GpModel::Linearise(const Eigen::MatrixXd& points, std::vector<LinGp>* out, LinearisationScratch* scratch) const {
  const int d = dimension(), c = d + 1;
  out->resize(points.rows());
  std::vector<int>& full = scratch->full_path;
  full.clear();
  for (int p = 0; p < static_cast<int>(points.rows()); ++p) {
    if (num_pivots() == 0 || !LineariseFromPivots(points.row(p).transpose(), &(*out)[p], scratch)) {
      full.push_back(p);
    }
  }
  const int fast = static_cast<int>(points.rows()) - static_cast<int>(full.size());
  if (full.empty()) return fast;
  // The O(N r) path, batched over the remaining points.
  const int P = static_cast<int>(full.size());
  Eigen::MatrixXd& w = scratch->cross;
  Eigen::MatrixXd& projection = scratch->projection;
  w.resize(num_points(), P * c);
  for (int p = 0; p < P; ++p) CrossCovariances(points.row(full[p]).transpose(), &w, p * c);
  Eigen::VectorXd& means = scratch->means;
  means.noalias() = w.transpose() * alpha_;  // [μ; ∇μ] per point, stacked
  const bool low_rank = basis_.cols() > 0;
  double inverse_noise = 1.0;
  if (low_rank) {
    projection.noalias() = basis_.transpose() * w;                          // A = Qᵀ W
    w.noalias() -= basis_ * projection;                                     // W⊥ = W - Q A
    basis_factor_.triangularView<Eigen::Lower>().solveInPlace(projection);  // L_G⁻¹ A
    inverse_noise = 1.0 / kernel_.noise_variance;
  } else {
    // No low-rank factor: the exact data term is the Gram matrix of L⁻¹ W (O(N²) per column).
    factor_.triangularView<Eigen::Lower>().solveInPlace(w);
  }
  for (int p = 0; p < P; ++p) {
    LinGp& lin = (*out)[full[p]];
    lin.mean = means.segment(p * c, c);
    const auto residual = w.middleCols(p * c, c);
    // V̂ = prior - (L_G⁻¹A)ᵀ(L_G⁻¹A) - W⊥ᵀW⊥/σ_n² (or - (L⁻¹W)ᵀ(L⁻¹W)), entry by entry:
    // (d+1)² dot products, no temporaries (a product expression per point allocated).
    lin.covariance.resize(c, c);
    for (int i = 0; i < c; ++i) {
      for (int k = i; k < c; ++k) {
        double v = -inverse_noise * residual.col(i).dot(residual.col(k));
        if (low_rank) v -= projection.col(p * c + i).dot(projection.col(p * c + k));
        lin.covariance(i, k) = v;
        lin.covariance(k, i) = v;
      }
    }
    // Prior covariance of [f; ∇f] at one point: diag(σ_f², σ_f²/ℓ²) (k and ∇k are
    // uncorrelated at coincident points); minus what the data explain.
    lin.covariance(0, 0) += kernel_.signal_variance;
    for (int i = 0; i < d; ++i) lin.covariance(1 + i, 1 + i) += kernel_.signal_variance * inverse_squared_lengths_(i);
    lin.covariance(0, 0) = std::max(lin.covariance(0, 0), 0.0);
  }
  return fast;
}

LinGp GpModel::Linearise(const Eigen::VectorXd& x) const {
  std::vector<LinGp> out;
  Linearise(x.transpose(), &out);
  return out[0];
}

}  // namespace nupmpc::gp
