#ifndef NUPMPC_CORE_ALGORITHMS_INTERIOR_POINT_ROWS_H_
#define NUPMPC_CORE_ALGORITHMS_INTERIOR_POINT_ROWS_H_

#include <vector>

#include "Eigen/Core"
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
  // Takes every row out of the method, for a new solve: Start takes back the rows that
  // still have a constraint (a row whose bound an update removed is never started again).
  void Forget();

  // Starts row r (prior `prior`, forward prediction `yhat` and prior variance `V_e` of its
  // value in the first pass) and aims it at the predictor's target. Rows whose value the
  // data fix (V_e = 0, e.g. outputs of a fixed x[0]) are left out: no barrier, no slack.
  // Keeps the prior's bounds and Gaussian part for the rest of the solve. Returns the
  // row's factor for the first pass, Gaussian part included.
  ScalarFactor Start(int r, const ScalarPrior& prior, double yhat, double V_e);
  bool active(int r) const { return (side_[r] & (kLower | kUpper)) != 0; }

  // Targets of the next direction: the predictor's (0), the corrector's after a predictor
  // direction (σμ - Δt_aff Δλ_aff), or a centrality correction of the current direction
  // at the trial step `trial` (Gondzio), which Reject() takes back with its direction.
  // Each also writes the factor of every started row for the Newton pass towards the new
  // targets into row_factor[r] (Gaussian part included; only that for a row left out):
  // one sweep over the rows' state, which long horizons stream from memory. Rows not
  // started since Forget (no constraint) keep their factor.
  void AimPredictor(ScalarFactor* row_factor);
  void AimCorrector(double sigma_mu, ScalarFactor* row_factor);
  void AimCentrality(double trial, double sigma_mu, ScalarFactor* row_factor);
  // Takes back the last AimCentrality and the direction it led to (the factors it wrote
  // stay: the next Aim writes them all).
  void Reject();

  // The direction of every row in the method from its new value z_new(r) of a pass with the
  // factors of the last Aim, and the largest step along it (MaxStep) in the same sweep.
  void TakeDirections(const Eigen::VectorXd& z_new);
  // The largest step along the last directions that keeps every slack and multiplier
  // nonnegative (∞ if none falls; one length for both: the dual residual of a quadratic
  // objective falls with the primal step only if the duals move alike); NaN after a
  // breakdown.
  double MaxStep() const { return max_step_; }
  // Average complementarity t λ over the bound sides, now or after a step.
  double Complementarity(double step = 0.0) const;
  // Moves the slacks and multipliers by the last directions.
  void Step(double step);

  // The row's region by its multipliers (after `step` along the last direction): at a
  // bound when the barrier's precision h_j there outweighs the precision 1/V_e of
  // everything else the pass knows about the row (the bound then determines the row's
  // value), else inside.
  Region RegionOf(int r, double V_e, double step = 0.0) const;
  double largest_multiplier() const;

 private:
  // What every sweep reads of a bound side. The backup of AimCentrality lives apart
  // (Kept): only it and Reject touch it.
  struct Side {
    double t = 0.0, lam = 0.0;    ///< slack and multiplier
    double dt = 0.0, dlam = 0.0;  ///< the last direction
    double target = 0.0;          ///< complementarity target of the next direction
    double bound = 0.0;           ///< a (lower side) or b (upper side)
  };
  struct Kept {
    double dt = 0.0, dlam = 0.0, target = 0.0;
  };
  // The prior's Gaussian part in canonical form (0, 0 when it has none).
  struct GaussianPart {
    double xi = 0.0, w = 0.0;
  };
  // Calls f(side, r's kept backup, sign) for each bound side of row r: sign +1 for the
  // lower bound (t = z - a), -1 for the upper (t = b - z). `Self` is this class, const or not.
  template <typename Self, typename F>
  static void ForSides(Self& self, int r, F&& f) {
    if (self.side_[r] & kLower) f(self.lo_[r], self.kept_lo_[r], 1.0);
    if (self.side_[r] & kUpper) f(self.up_[r], self.kept_up_[r], -1.0);
  }
  // The factor of row r towards its sides' targets, Gaussian part included.
  ScalarFactor Factor(int r) const;

  // side_[r]: kLower | kUpper for the bound sides present, kStarted for every row Start saw
  // since Forget (a row left out has only that); 0: not started.
  static constexpr unsigned char kLower = 1, kUpper = 2, kStarted = 4;
  std::vector<unsigned char> side_;
  std::vector<Side> lo_, up_;
  std::vector<Kept> kept_lo_, kept_up_;
  std::vector<GaussianPart> gaussian_;
  double max_step_ = kInfinity, kept_max_step_ = kInfinity;
};

// Whether a row's prior is one the interior-point rows handle: none (a Gaussian part at
// most) or a hard bound (half-space, or a box whose width's square is a normal number).
bool InteriorPointHandles(const ScalarPrior& prior);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_INTERIOR_POINT_ROWS_H_
