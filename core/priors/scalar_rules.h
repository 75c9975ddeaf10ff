#ifndef NUPMPC_CORE_PRIORS_SCALAR_RULES_H_
#define NUPMPC_CORE_PRIORS_SCALAR_RULES_H_

// Per-scalar rules of nup-algorithms.md §5 (costs, NUP updates, deciding rules) and
// §9.4–9.5 (IFFBDD dual NUP factors and γ rules). All functions are pure, branchy
// scalar code with no allocation; `slope` is passed explicitly because IBFFD adapts it
// and IAKE replaces a hard slope by a finite one.

#include <cstdint>

#include "core/priors/scalar_factor.h"
#include "core/priors/scalar_prior.h"

namespace nupmpc::core {

// Which smooth piece or kink of κ a value lies in. Used to detect when the set of
// active constraints has settled and to build the active-set polish factors.
enum class Region : std::int8_t {
  kBelow = -2,    ///< left of the lower kink (linear piece with slope -s, or Huber's left arm)
  kAtLower = -1,  ///< at the lower kink (lower bound; L1 centre)
  kInside = 0,    ///< between the kinks (no kink-related cost; Huber's quadratic part)
  kAtUpper = 1,   ///< at the upper kink
  kAbove = 2,     ///< right of the upper kink
};

// Cost φ(z): Gaussian part plus the penalty of a finite-slope kind; hard constraints
// cost nothing (their violation is reported separately).
double PriorCost(const ScalarPrior& prior, double z);

// Distance of z to the feasible set of a hard constraint (0 for every other prior).
double HardViolation(const ScalarPrior& prior, double z);

// Folds the prior's Gaussian part into an extrinsic message (§5.3): the message the
// kind's deciding rule sees.
struct Message {
  double m;
  double V;
};
Message FoldGaussianPart(const ScalarPrior& prior, Message extrinsic);

// Deciding rule: z = prox(κ + Gaussian part; m_e, V_e) with the given slope (§5.1, §5.3).
struct Decision {
  double z;
  Region region;
};
Decision Decide(const ScalarPrior& prior, double slope, Message extrinsic);

// NUP update of the kind's part at the current estimate x (§5.1): the moment part of
// the scalar's factor for the next Gaussian pass. V = ∞ for kind kNone. EM variants of
// the non-convex kinds also use the scalar's posterior variance (ignored otherwise).
ScalarFactor NupUpdate(const ScalarPrior& prior, double slope, double x, double posterior_variance = 0.0);

// The prior's full factor for a Gaussian pass: the kind's NUP part times the Gaussian part.
inline ScalarFactor WithGaussianPart(const ScalarPrior& prior, ScalarFactor nup) {
  if (prior.has_gaussian()) {
    nup.xi += prior.mean / prior.variance;
    nup.w += 1.0 / prior.variance;
  }
  return nup;
}

// The exact factor of κ + Gaussian part restricted to one region: pinned at a kink, or
// the Gaussian part times the linear (or Huber-quadratic) piece. Used by the polish.
ScalarFactor PieceFactor(const ScalarPrior& prior, double slope, Region region);

// The primal-dual active-set step of the polish: the region a scalar gets for the next
// polish pass, given the region it was solved in and the one the deciding rule chose at
// the candidate. A box scalar pinned at one bound whose rule now says the other side is
// released to its inside first instead of being pinned across the box: jumping straight
// across made the correction cycle with period two on the masses closed loop (residual =
// the box width every round). Optimality is still decided by the deciding-rule residual.
Region NextPolishRegion(const ScalarPrior& prior, Region solved, Region decided);

// IFFBDD (§9.4): canonical factor of the kind's dual NUP at multiplier y_dual with scale γ.
ScalarFactor DualNupFactor(const ScalarPrior& prior, double y_dual, double gamma);
// IFFBDD (§9.5): the γ an output needs at the (folded) extrinsic message; γ ← max(γ, this).
double GammaNext(const ScalarPrior& prior, Message folded);
// IFFBDD: the starting γ (hard box (b-a)/2, soft box floor (b-a)/2, else 1e-12).
double GammaInitial(const ScalarPrior& prior);

// IBFFD (§8.3): the smallest slope for which the deciding rule returns a feasible value
// of a hard constraint at the folded message (only meaningful when it is violated).
double RequiredSlope(const ScalarPrior& prior, Message folded);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_PRIORS_SCALAR_RULES_H_
