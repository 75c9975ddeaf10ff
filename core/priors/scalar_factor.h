#ifndef NUPMPC_CORE_PRIORS_SCALAR_FACTOR_H_
#define NUPMPC_CORE_PRIORS_SCALAR_FACTOR_H_

#include "core/priors/scalar_prior.h"

namespace nupmpc::core {

// A Gaussian factor on one scalar z, as a product of a moment part and a canonical part:
//   N(z; m, V) · exp(-w z²/2 + xi z),   V ∈ [0, ∞] (V = ∞: no moment part), w ≥ 0.
// V = 0 pins z to m. The moment part carries NUP Gaussians (which may reach V = 0
// exactly at a bound: nup-algorithms.md §12.1 forbids 1/V), the canonical part carries
// Gaussian priors, dual-NUP factors and pure linear terms (w = 0).
struct ScalarFactor {
  double m = 0.0;
  double V = kInfinity;
  double xi = 0.0;
  double w = 0.0;

  bool pinned() const { return V == 0.0; }
  bool empty() const { return V == kInfinity && w == 0.0 && xi == 0.0; }

  static ScalarFactor Pinned(double value) { return {value, 0.0, 0.0, 0.0}; }
  static ScalarFactor Canonical(double xi, double w) { return {0.0, kInfinity, xi, w}; }
  // The Gaussian part of a prior in canonical form (empty if it has none).
  static ScalarFactor GaussianPart(const ScalarPrior& p) {
    if (!p.has_gaussian()) return {};
    return Canonical(p.mean / p.variance, 1.0 / p.variance);
  }
};

// Moment form (mean, variance) of a factor whose total precision is > 0 or which is
// pinned. `ok` is false when the factor has no finite moment form (V = ∞ and w = 0).
struct MomentForm {
  double mean = 0.0;
  double variance = 0.0;
  bool ok = false;
};
inline MomentForm ToMoment(const ScalarFactor& f) {
  if (f.V == kInfinity) {
    if (f.w > 0.0) return {f.xi / f.w, 1.0 / f.w, true};
    return {};
  }
  const double den = 1.0 + f.V * f.w;  // product form: no 1/V
  return {(f.m + f.V * f.xi) / den, f.V / den, true};
}

// Posterior mean of z when the factor meets a Gaussian message N(m_e, V_e), V_e > 0.
inline double CombineWithMessage(const ScalarFactor& f, double m_e, double V_e) {
  if (f.V == 0.0) return f.m;
  if (f.V == kInfinity) return (m_e + V_e * f.xi) / (1.0 + V_e * f.w);
  // moment part (m, V) and canonical part: precision 1/V_e + 1/V + w, written without 1/V.
  return (f.V * m_e + V_e * f.m + V_e * f.V * f.xi) / (f.V + V_e + V_e * f.V * f.w);
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_PRIORS_SCALAR_FACTOR_H_
