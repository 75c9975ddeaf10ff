#ifndef NUPMPC_TESTS_UTIL_DAC_PLANT_H_
#define NUPMPC_TESTS_UTIL_DAC_PLANT_H_

// The digital-to-analog conversion example of [KL] §V-A (nup-algorithms.md §7.1): the
// third-order filter (85) as printed (DC gain 0.8967, relative degree 3) and the target
// 0.8967·0.5 + 0.3 sin(2π·2 Hz·t) sampled every 3 ms.

#include <cmath>

#include "Eigen/LU"
#include "core/problem.h"

namespace nupmpc::testing {

// Horizon K, one input and one output, no priors set (all free); x[0] is the steady state
// for u ≡ 0.5.
inline core::Problem DacPlant(int K) {
  core::Problem p = core::Problem::TimeInvariant(3, 1, 1, K);
  p.A[0] << 0.7967, -6.3978, -94.2123, 0.0027, 0.9902, -0.1467, 0.0, 0.0030, 0.9999;
  p.B[0] << 0.0027, 0.0, 0.0;
  p.C[0] << 0.0, 0.0, 35037.9;
  p.initial_mean = (Eigen::Matrix3d::Identity() - p.A[0]).partialPivLu().solve(0.5 * p.B[0]);
  return p;
}

inline double DacTarget(int t) { return 0.8967 * 0.5 + 0.3 * std::sin(2.0 * M_PI * 2.0 * 0.003 * t); }

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_DAC_PLANT_H_
