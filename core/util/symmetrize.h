#ifndef NUPMPC_CORE_UTIL_SYMMETRIZE_H_
#define NUPMPC_CORE_UTIL_SYMMETRIZE_H_

#include "Eigen/Core"

namespace nupmpc::core {

// V ← (V + Vᵀ)/2 in place, without the temporary that `(V + V.transpose())` would need
// (nup-algorithms.md §12.3: symmetrise after every step).
template <typename Derived>
inline void SymmetrizeInPlace(Eigen::MatrixBase<Derived>& V) {
  const Eigen::Index n = V.rows();
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = j + 1; i < n; ++i) {
      const double avg = 0.5 * (V(i, j) + V(j, i));
      V(i, j) = avg;
      V(j, i) = avg;
    }
  }
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_UTIL_SYMMETRIZE_H_
