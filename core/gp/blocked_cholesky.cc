#include "core/gp/blocked_cholesky.h"

#include <algorithm>

#include "Eigen/Cholesky"
#include "absl/strings/str_cat.h"

namespace nupmpc::gp {
namespace {

using Index = Eigen::Index;
constexpr Index kBlock = kCholeskyBlock;

}  // namespace

absl::Status BlockedCholesky(Eigen::Ref<Eigen::MatrixXd> a, const core::Deadline& stop, absl::string_view what) {
  const Index n = a.rows();
  const auto where = [&](Index column) {
    return absl::StrCat("factorising ", what, " (column ", column, " of ", n, ")");
  };
  for (Index j = 0; j < n; j += kBlock) {
    if (stop.Requested()) return stop.Stopped(where(j));
    const Index b = std::min(kBlock, n - j), rest = n - j - b;
    Eigen::Ref<Eigen::MatrixXd> diagonal = a.block(j, j, b, b);
    const Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(diagonal);  // in place
    if (llt.info() != Eigen::Success) {
      return absl::FailedPreconditionError(
          absl::StrCat(what, " is not positive definite in floating point (at columns ", j, "..", j + b - 1, ")"));
    }
    if (rest == 0) break;
    auto panel = a.block(j + b, j, rest, b);
    diagonal.transpose().triangularView<Eigen::Upper>().solveInPlace<Eigen::OnTheRight>(panel);  // A21 L11⁻ᵀ
    // A22 -= A21 A21ᵀ (lower triangle), one column strip per check.
    for (Index s = 0; s < rest; s += kBlock) {
      if (s > 0 && stop.Requested()) return stop.Stopped(where(j));
      const Index w = std::min(kBlock, rest - s), below = rest - s - w;
      const auto strip = panel.middleRows(s, w);
      a.block(j + b + s, j + b + s, w, w).selfadjointView<Eigen::Lower>().rankUpdate(strip, -1.0);
      if (below > 0)
        a.block(j + b + s + w, j + b + s, below, w).noalias() -= panel.bottomRows(below) * strip.transpose();
    }
  }
  return absl::OkStatus();
}

absl::Status InverseFromCholesky(Eigen::Ref<Eigen::MatrixXd> a, Eigen::MatrixXd* row_block, const core::Deadline& stop,
                                 absl::string_view what) {
  const Index n = a.rows();
  Eigen::MatrixXd& t = *row_block;
  if (t.rows() < kBlock || t.cols() < n + kBlock) {
    return absl::InternalError(
        absl::StrCat("InverseFromCholesky: scratch is ", t.rows(), "x", t.cols(), ", needs ", kBlock, "x", n + kBlock));
  }
  const auto where = [&](const char* step, Index row) {
    return absl::StrCat("inverting ", what, " (", step, ", row ", row, " of ", n, ")");
  };
  // 1. X = L⁻¹, block row I at a time: X[I, <I] = -L_II⁻¹ L[I, <I] X[<I, <I], X_II = L_II⁻¹.
  // Rows above I already hold X; rows from I on still hold L.
  for (Index i0 = 0; i0 < n; i0 += kBlock) {
    const Index b = std::min(kBlock, n - i0);
    for (Index s0 = 0; s0 < i0; s0 += kBlock) {
      if (stop.Requested()) return stop.Stopped(where("L⁻¹", i0));
      const Index w = std::min(kBlock, i0 - s0), s1 = s0 + w;
      auto out = t.block(0, s0, b, w);
      out.noalias() = a.block(i0, s0, b, w) * a.block(s0, s0, w, w).triangularView<Eigen::Lower>();
      if (i0 > s1) out.noalias() += a.block(i0, s1, b, i0 - s1) * a.block(s1, s0, i0 - s1, w);
    }
    auto l_ii = a.block(i0, i0, b, b).triangularView<Eigen::Lower>();
    if (i0 > 0) {
      l_ii.solveInPlace(t.block(0, 0, b, i0));
      a.block(i0, 0, b, i0) = -t.block(0, 0, b, i0);
    }
    auto inverse_ii = t.block(0, 0, b, b);
    inverse_ii.setIdentity();
    l_ii.solveInPlace(inverse_ii);
    a.block(i0, i0, b, b).triangularView<Eigen::Lower>() = inverse_ii;
  }
  // 2. (L Lᵀ)⁻¹ = Xᵀ X, block row I at a time: C[I, ≤I] = X[≥I, I]ᵀ X[≥I, ≤I]. It reads only
  // rows from I on, which still hold X.
  for (Index i0 = 0; i0 < n; i0 += kBlock) {
    const Index b = std::min(kBlock, n - i0), i1 = i0 + b, below = n - i1;
    auto x_ii = a.block(i0, i0, b, b).triangularView<Eigen::Lower>();
    for (Index s0 = 0; s0 < i0; s0 += kBlock) {
      if (stop.Requested()) return stop.Stopped(where("L⁻ᵀL⁻¹", i0));
      const Index w = std::min(kBlock, i0 - s0);
      auto out = t.block(0, s0, b, w);
      out.noalias() = x_ii.transpose() * a.block(i0, s0, b, w);
      if (below > 0) out.noalias() += a.block(i1, i0, below, b).transpose() * a.block(i1, s0, below, w);
    }
    if (stop.Requested()) return stop.Stopped(where("L⁻ᵀL⁻¹", i0));
    auto x_ii_dense = t.block(0, n, b, b);  // X_II with its zeros, for the product below
    x_ii_dense = x_ii;
    auto diagonal = t.block(0, i0, b, b);
    diagonal.noalias() = x_ii.transpose() * x_ii_dense;
    if (below > 0) diagonal.noalias() += a.block(i1, i0, below, b).transpose() * a.block(i1, i0, below, b);
    if (i0 > 0) a.block(i0, 0, b, i0) = t.block(0, 0, b, i0);
    a.block(i0, i0, b, b).triangularView<Eigen::Lower>() = diagonal;
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::gp
