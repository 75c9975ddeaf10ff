#ifndef NUPMPC_CORE_PRIORS_SCALAR_PRIOR_H_
#define NUPMPC_CORE_PRIORS_SCALAR_PRIOR_H_

#include <cstdint>
#include <limits>

namespace nupmpc::core {

inline constexpr double kInfinity = std::numeric_limits<double>::infinity();

// The non-Gaussian part of a scalar prior. Costs κ(z) use the one slope unit of
// nup-algorithms.md §1.1 (the outside slope s, which is also the exact-penalty
// weight); slope = +∞ means a hard constraint (only for half-spaces and boxes).
enum class PriorKind : std::uint8_t {
  kNone,     ///< only the Gaussian part (or nothing: a free scalar)
  kL1,       ///< s |z - lower|                       (Laplace; `lower` is the centre)
  kHuber,    ///< Huber around `lower` with radius r: z²/(2r²)+s²r²/2 inside, s|z| outside
  kAtLeast,  ///< z ≥ lower  (cost s (lower - z)_+)
  kAtMost,   ///< z ≤ upper  (cost s (z - upper)_+)
  kBox,      ///< lower ≤ z ≤ upper (cost s dist(z, [lower, upper]))
  // Non-convex (IAKE only; nup-algorithms.md §5.1, §7). `em` picks the estimation variant.
  kPlainNuv,     ///< sparsity: favours z = lower exactly (cost log|z - lower|)
  kSmoothedNuv,  ///< plain NUV with its variance floored at radius² (no pull inside radius)
  kLp,           ///< s |z - lower|^exponent, 0 < exponent ≤ 1
  kBinary,       ///< z ∈ {lower, upper} (an indicator; plans are rounded to the levels)
};

// Whether a kind is non-convex (only IAKE's NUP updates handle it).
constexpr bool IsNonconvex(PriorKind kind) {
  return kind == PriorKind::kPlainNuv || kind == PriorKind::kSmoothedNuv || kind == PriorKind::kLp ||
         kind == PriorKind::kBinary;
}

// A prior on one scalar (one input or output component at one step): an optional
// Gaussian part N(mean, variance) times an optional kind κ. Gaussian priors
// (quadratic costs, tracking references) are kind kNone with a finite variance;
// a free scalar has kind kNone and variance +∞. A constrained scalar that also has
// a quadratic cost carries both parts (nup-algorithms.md §5.3).
//
// Stored flat (one per scalar per step) so that NUP updates are a switch over
// `kind` with no virtual dispatch and no allocation.
struct ScalarPrior {
  // (Doubles first, the byte-sized fields last: 72 bytes instead of 88, and a session holds
  // several per scalar of its horizon.)
  double mean = 0.0;            ///< Gaussian part: mean (reference)
  double variance = kInfinity;  ///< Gaussian part: variance > 0 (1/weight); +∞ = none
  double lower = 0.0;           ///< kAtLeast/kBox lower bound; kL1/kHuber centre
  double upper = 0.0;           ///< kAtMost/kBox upper bound
  double slope = kInfinity;     ///< outside slope s > 0; +∞ = hard (half-space/box only)
  double radius = 1.0;          ///< kHuber radius r > 0; kSmoothedNuv radius
  double exponent = 1.0;        ///< kLp exponent p, 0 < p ≤ 1
  // kBinary: the NUP variance IAKE starts from (0: (upper - lower)²). The binaries of an
  // M-level input start from slightly different values to break their symmetry.
  double initial_variance = 0.0;
  PriorKind kind = PriorKind::kNone;
  // Non-convex kinds: expectation maximisation (type-II, uses the posterior variance;
  // [KL] recommends it: far better plans, slower to settle) or alternating maximisation
  // (joint MAP: settles in tens of iterations).
  bool em = true;
  // kBinary input: this binary and the next input component at the same step are summed
  // into one M-level input (core/model/multilevel_inputs.h). The plan then rounds the
  // sum to the nearest level instead of each binary on its own: two binaries stuck
  // symmetrically at ½ mean the middle level, not both low or both high.
  bool rounds_with_next = false;

  bool has_gaussian() const { return variance < kInfinity; }
  bool is_hard() const { return slope == kInfinity; }
  bool is_constraint() const {
    return kind == PriorKind::kAtLeast || kind == PriorKind::kAtMost || kind == PriorKind::kBox;
  }
  bool is_discrete() const { return kind == PriorKind::kBinary; }

  static ScalarPrior Free() { return {}; }
  static ScalarPrior Gaussian(double mean, double variance) {
    ScalarPrior p;
    p.mean = mean;
    p.variance = variance;
    return p;
  }
  static ScalarPrior Box(double lower, double upper, double slope = kInfinity) {
    ScalarPrior p;
    p.kind = PriorKind::kBox;
    p.lower = lower;
    p.upper = upper;
    p.slope = slope;
    return p;
  }
  static ScalarPrior AtLeast(double lower, double slope = kInfinity) {
    ScalarPrior p;
    p.kind = PriorKind::kAtLeast;
    p.lower = lower;
    p.slope = slope;
    return p;
  }
  static ScalarPrior AtMost(double upper, double slope = kInfinity) {
    ScalarPrior p;
    p.kind = PriorKind::kAtMost;
    p.upper = upper;
    p.slope = slope;
    return p;
  }
  static ScalarPrior L1(double centre, double slope) {
    ScalarPrior p;
    p.kind = PriorKind::kL1;
    p.lower = centre;
    p.slope = slope;
    return p;
  }
  static ScalarPrior Huber(double centre, double radius, double slope) {
    ScalarPrior p;
    p.kind = PriorKind::kHuber;
    p.lower = centre;
    p.radius = radius;
    p.slope = slope;
    return p;
  }
  static ScalarPrior PlainNuv(double centre, bool em = true) {
    ScalarPrior p;
    p.kind = PriorKind::kPlainNuv;
    p.lower = centre;
    p.em = em;
    return p;
  }
  static ScalarPrior SmoothedNuv(double centre, double radius, bool em = true) {
    ScalarPrior p = PlainNuv(centre, em);
    p.kind = PriorKind::kSmoothedNuv;
    p.radius = radius;
    return p;
  }
  static ScalarPrior Lp(double centre, double exponent, double slope) {
    ScalarPrior p;
    p.kind = PriorKind::kLp;
    p.lower = centre;
    p.exponent = exponent;
    p.slope = slope;
    return p;
  }
  static ScalarPrior Binary(double a, double b, bool em = true) {
    ScalarPrior p;
    p.kind = PriorKind::kBinary;
    p.lower = a;
    p.upper = b;
    p.em = em;
    return p;
  }
  // Adds a Gaussian part (quadratic cost ½(z-mean)²/variance) to any kind.
  ScalarPrior WithGaussian(double m, double v) const {
    ScalarPrior p = *this;
    p.mean = m;
    p.variance = v;
    return p;
  }
};

const char* PriorKindName(PriorKind kind);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_PRIORS_SCALAR_PRIOR_H_
