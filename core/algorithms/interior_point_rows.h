#ifndef NUPMPC_CORE_ALGORITHMS_INTERIOR_POINT_ROWS_H_
#define NUPMPC_CORE_ALGORITHMS_INTERIOR_POINT_ROWS_H_

#include <vector>

#include "core/priors/scalar_factor.h"
#include "core/priors/scalar_prior.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

// The per-row arithmetic of a primal-dual interior-point method (Mehrotra's predictor-
// corrector with Gondzio's centrality correctors: Wright, "Primal-Dual Interior-Point
// Methods", SIAM 1997, ch. 10 and 11; Gondzio, Comput. Optim. Appl. 6, 1996) on the hard
// bounds of the rows z = cᵀx + d of a linear-quadratic problem, for IFFBDD's graph.
//
// Each bound side j of a row (lower a, upper b) has a slack t_j > 0 and a multiplier
// λ_j > 0 with a - z + t_lo = 0 and z - b + t_up = 0 at convergence; a Newton direction
// aims at the complementarity target τ_j: (t + Δt)(λ + Δλ) ≈ t λ + λ Δt + t Δλ = τ_j (the
// predictor aims at 0, the corrector at σμ - Δt_aff Δλ_aff, a centrality corrector adds
// the distance of the trial products to [β_min σμ, β_max σμ]). With h_j = λ_j / t_j, the
// direction's condensed system is the LQ problem whose row r carries the canonical
// Gaussian factor exp(-h z²/2 + q z),
//   h = h_lo + h_up,   q = h_lo (a + t_lo) + τ_lo / t_lo + h_up (b - t_up) - τ_up / t_up,
// so one Kalman pass with these factors solves it exactly (a second target needs only a
// means pass with the same gains), and from the row's new value z⁺
//   Δt_lo = z⁺ - a - t_lo,   Δt_up = b - z⁺ - t_up,   Δλ_j = (τ_j - t_j λ_j - λ_j Δt_j) / t_j.
// The current z drops out of both (the primal residuals are carried by the slacks): the
// plan is the only primal state the caller keeps, moved by the same step.
//
// Sized once; no method allocates.
class InteriorPointRows {
 public:
  void Resize(int rows);

  // Starts row r (prior `prior`, forward prediction `yhat` and prior variance `V_e` of its
  // value in the first pass) and aims it at the predictor's target. Rows whose value the
  // data fix (V_e = 0, e.g. outputs of a fixed x[0]) are left out: no factor, no slack.
  // Returns the row's factor for the first pass.
  ScalarFactor Start(int r, const ScalarPrior& prior, double yhat, double V_e);
  bool active(int r) const { return side_[r] != 0; }

  // Targets of the next direction: the predictor's (0), the corrector's after a predictor
  // Direction() (σμ - Δt_aff Δλ_aff), or a centrality correction of the current direction
  // at the trial step `trial` (Gondzio), which Reject() takes back with its direction.
  void AimPredictor();
  void AimCorrector(double sigma_mu);
  void AimCentrality(double trial, double sigma_mu);
  void Reject();

  // The row's factor for a Newton pass towards the current targets.
  ScalarFactor Factor(int r, const ScalarPrior& prior) const;
  // The direction of row r from its new value z⁺ of a pass with Factor(r, ·).
  void Direction(int r, const ScalarPrior& prior, double z_new);
  // The largest step along the rows' last Direction() that keeps every slack and
  // multiplier nonnegative (∞ if none falls; one length for both: the dual residual of a
  // quadratic objective falls with the primal step only if the duals move alike).
  double MaxStep() const;
  // Average complementarity t λ over the bound sides, now or after a step.
  double Complementarity(double step = 0.0) const;
  // Moves the slacks and multipliers by the last Direction().
  void Step(double step);

  // The row's region by its multipliers (after `step` along the last Direction()): at a
  // bound when the barrier's precision h_j there outweighs the precision 1/V_e of
  // everything else the pass knows about the row (the bound then determines the row's
  // value), else inside.
  Region RegionOf(int r, double V_e, double step = 0.0) const;
  double largest_multiplier() const;

 private:
  struct Side {
    double t = 0.0, lam = 0.0;    ///< slack and multiplier
    double dt = 0.0, dlam = 0.0;  ///< the last Direction()
    double target = 0.0;          ///< complementarity target of the next direction
    double kept_dt = 0.0, kept_dlam = 0.0, kept_target = 0.0;  ///< before AimCentrality
  };
  // Calls f(side, bound, sign) for each bound side of row r: sign +1 for the lower bound
  // (t = z - a), -1 for the upper (t = b - z). `Self` is this class, const or not.
  template <typename Self, typename F>
  static void ForSides(Self& self, int r, const ScalarPrior& prior, F&& f) {
    if (self.side_[r] & kLower) f(self.lo_[r], prior.lower, 1.0);
    if (self.side_[r] & kUpper) f(self.up_[r], prior.upper, -1.0);
  }

  // side_[r]: kLower | kUpper for the bound sides present; 0: the row is not in the method.
  static constexpr unsigned char kLower = 1, kUpper = 2;
  std::vector<unsigned char> side_;
  std::vector<Side> lo_, up_;
};

// Whether a row's prior is one the interior-point rows handle: none (a Gaussian part at
// most) or a hard bound (half-space, or a box whose width's square is a normal number).
bool InteriorPointHandles(const ScalarPrior& prior);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_INTERIOR_POINT_ROWS_H_
