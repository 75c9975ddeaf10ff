#ifndef NUPMPC_CORE_MESSAGE_PASSING_FIXED_SIZE_H_
#define NUPMPC_CORE_MESSAGE_PASSING_FIXED_SIZE_H_

// Dispatch of the O(N) recursions to fixed-size Eigen kernels for small state dimensions.
// Dynamic-size Eigen products of 3×3 or 12×12 matrices spend most of their time in size
// checks and dispatch; with the size known at compile time the same code is unrolled and
// vectorised. Fixed-size scratch lives on the stack (no heap), the dynamic fallback uses
// the workspace, and both share one templated body.

#include <utility>

#include "Eigen/Core"

namespace nupmpc::core {

// State sizes with a compiled kernel (the rest use Eigen::Dynamic). The ThreadSanitizer
// build compiles only the dynamic kernel (CMake option NUPMPC_FIXED_SIZE_KERNELS): it checks
// the server's threading, and a kernel's size changes only the arithmetic of one solve on
// one worker; the nine fixed-size copies would double its compile time in CI.
#if defined(NUPMPC_DYNAMIC_KERNELS_ONLY)
#define NUPMPC_FIXED_STATE_SIZES(X)
#else
#define NUPMPC_FIXED_STATE_SIZES(X) X(2) X(3) X(4) X(5) X(6) X(8) X(12) X(16) X(20)
#endif

template <int MS>
using StateMatrix = Eigen::Matrix<double, MS, MS>;
template <int MS>
using StateVector = Eigen::Matrix<double, MS, 1>;

// Calls f.template operator()<MS>() with MS = M if M has a fixed kernel, else Eigen::Dynamic.
template <typename F>
decltype(auto) DispatchStateSize(int M, F&& f) {
  switch (M) {
#define NUPMPC_CASE(K) \
  case K:              \
    return std::forward<F>(f).template operator()<K>();
    NUPMPC_FIXED_STATE_SIZES(NUPMPC_CASE)
#undef NUPMPC_CASE
    default:
      return std::forward<F>(f).template operator()<Eigen::Dynamic>();
  }
}

// The state size to run an augmented model at. Eigen's fixed-size kernels are fastest at
// whole multiples of the SIMD width: a 15×15 time update with its rank-1 updates is slower
// than the same work at 16×16 (13, 14 → 16 and 9–11 → 12 likewise). Padding with inert states (no dynamics, no input,
// no observation, zero variance) leaves every message on the real states unchanged.
constexpr int PaddedStateSize(int M) {
  if (M >= 9 && M <= 11) return 12;
  if (M >= 13 && M <= 15) return 16;
  return M;
}

// A read-only view of a dense column-major M×K block as a (possibly fixed-size) matrix.
template <int Rows, int Cols>
Eigen::Map<const Eigen::Matrix<double, Rows, Cols>> ConstView(const double* data, int rows, int cols) {
  return Eigen::Map<const Eigen::Matrix<double, Rows, Cols>>(data, rows, cols);
}

// A writable view of the same kind. Writing a fixed-size vector through it (rather than
// into a dynamic block) keeps the assignment at its compile-time size: through a dynamic
// destination Eigen also compiles a whole-packet loop that can never run for a short
// vector, and GCC 12 warns (-Warray-bounds) about that loop's 64-byte loads under AVX-512.
template <int Rows, int Cols>
Eigen::Map<Eigen::Matrix<double, Rows, Cols>> View(double* data, int rows, int cols) {
  return Eigen::Map<Eigen::Matrix<double, Rows, Cols>>(data, rows, cols);
}

// dst = lhs · rhs for state-sized matrices. Even for fixed sizes Eigen takes its blocked
// GEMM path (packing, made for large matrices) once rows + cols + depth ≥ 20; for 8..16
// the coefficient-based product is faster (no packing for matrices that fit in
// registers and L1); from 20 on GEMM's packing pays off (`nupmpc-bench --scaling` prints
// the kernels' rate at M = 20). Dynamic sizes (large M) keep GEMM.
template <int MS, typename Dst, typename Lhs, typename Rhs>
void StateProduct(Dst&& dst, const Lhs& lhs, const Rhs& rhs) {
  if constexpr (MS == Eigen::Dynamic || MS >= 20) {
    dst.noalias() = lhs * rhs;
  } else {
    dst.noalias() = lhs.lazyProduct(rhs);
  }
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_MESSAGE_PASSING_FIXED_SIZE_H_
