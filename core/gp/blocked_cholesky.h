#ifndef NUPMPC_CORE_GP_BLOCKED_CHOLESKY_H_
#define NUPMPC_CORE_GP_BLOCKED_CHOLESKY_H_

// Dense symmetric positive-definite factorisation and inverse that a deadline or a cancel
// flag can stop. The GP's K + σ_n² I is P × P (P up to the server's max_gp_points), and
// factorising or inverting it is O(P³): done in one Eigen call it holds a worker for as long
// as it takes, whatever the caller's deadline. Here the work runs in blocks of at most
// kBlock × kBlock × P multiply-adds, with a deadline check (core/public/deadline.h) between blocks, so that a
// worker is free within one such block after the deadline.

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "core/public/deadline.h"

namespace nupmpc::gp {

// Panel and strip width of the blocked algorithms below: wide enough for GEMM speed, narrow
// enough that the work between two checks stays small at the largest admissible P.
inline constexpr int kCholeskyBlock = 64;

// In-place lower Cholesky factor of the symmetric matrix whose lower triangle is in `a`
// (the strict upper triangle is neither read nor written): right-looking, Eigen's LLT on
// each diagonal block, a triangular solve of the panel below it and a rank-k update of the
// trailing matrix in column strips. FAILED_PRECONDITION when `a` is not positive definite
// in floating point; the deadline's status when it fired. `what` names the matrix in
// messages.
absl::Status BlockedCholesky(Eigen::Ref<Eigen::MatrixXd> a, const core::Deadline& stop, absl::string_view what);

// From the lower Cholesky factor L in `a`, the lower triangle of (L Lᵀ)⁻¹ = L⁻ᵀ L⁻¹ in
// place: first L⁻¹ by block rows (left-looking), then L⁻ᵀ L⁻¹ by block rows, each in
// strips. `row_block` is kCholeskyBlock × P scratch (resized once by the caller; not
// resized here). Returns the deadline's status when it fired (`a` is then garbage).
absl::Status InverseFromCholesky(Eigen::Ref<Eigen::MatrixXd> a, Eigen::MatrixXd* row_block, const core::Deadline& stop,
                                 absl::string_view what);

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_BLOCKED_CHOLESKY_H_
