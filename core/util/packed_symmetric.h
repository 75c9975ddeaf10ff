#ifndef NUPMPC_CORE_UTIL_PACKED_SYMMETRIC_H_
#define NUPMPC_CORE_UTIL_PACKED_SYMMETRIC_H_

#include "Eigen/Core"

namespace nupmpc::core {

// Symmetric M × M matrices stored per horizon step keep only their lower triangle, column
// by column (M(M+1)/2 doubles): a long horizon's sweeps then move about half the bytes.
inline Eigen::Index PackedSymmetricSize(Eigen::Index M) { return M * (M + 1) / 2; }

// Writes the lower triangle of `W` (symmetric) to `packed` (PackedSymmetricSize values).
template <typename Derived>
inline void PackLower(const Eigen::MatrixBase<Derived>& W, double* packed) {
  const Eigen::Index M = W.rows();
  for (Eigen::Index j = 0; j < M; ++j) {
    Eigen::Map<Eigen::VectorXd>(packed, M - j) = W.col(j).tail(M - j);
    packed += M - j;
  }
}

// The inverse of PackLower: the whole symmetric matrix (bit-identical to a symmetric `W`).
template <typename Derived>
inline void UnpackSymmetric(const double* packed, Eigen::MatrixBase<Derived>& W) {
  const Eigen::Index M = W.rows();
  for (Eigen::Index j = 0; j < M; ++j) {
    const Eigen::Map<const Eigen::VectorXd> lower(packed, M - j);
    W.col(j).tail(M - j) = lower;
    W.row(j).tail(M - j - 1) = lower.tail(M - j - 1).transpose();
    packed += M - j;
  }
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_UTIL_PACKED_SYMMETRIC_H_
