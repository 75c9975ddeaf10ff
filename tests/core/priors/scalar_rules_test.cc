// Scalar checks of nup-algorithms.md §5.2 / §13.1: the box and half-space theorems of [KL],
// deciding rules as proximal operators (against brute-force minimisation), NUP updates.
#include "core/priors/scalar_rules.h"

#include <cmath>
#include <random>

#include "gtest/gtest.h"

namespace nupmpc::core {
namespace {

// Alternates x ← posterior of N(m,V)·N(μ,σ²), (m,V) ← NUP update(x) (§5.2), product form.
double NupFixedPoint(const ScalarPrior& prior, double slope, double mu, double sigma2, int iterations) {
  double x = mu;
  for (int i = 0; i < iterations; ++i) {
    const ScalarFactor f = NupUpdate(prior, slope, x);
    x = (f.m * sigma2 + mu * f.V) / (f.V + sigma2);
  }
  return x;
}

TEST(ScalarTheorems, BoxFixedPointMatchesTheorem1) {
  // a = -1, b = 1, γ = 1 (s = 2γ = 2), μ = 1.5: outside iff σ² < 0.5/(2γ) = 0.25.
  const ScalarPrior box = ScalarPrior::Box(-1.0, 1.0, 2.0);
  EXPECT_NEAR(NupFixedPoint(box, 2.0, 1.5, 0.2, 20000), 1.1, 1e-8);
  EXPECT_NEAR(NupFixedPoint(box, 2.0, 1.5, 0.3125, 20000), 1.0, 1e-8);
  // The deciding rule is the exact minimiser and agrees with the fixed point.
  EXPECT_NEAR(Decide(box, 2.0, {1.5, 0.2}).z, 1.1, 1e-15);
  EXPECT_DOUBLE_EQ(Decide(box, 2.0, {1.5, 0.3125}).z, 1.0);
}

TEST(ScalarTheorems, HalfSpaceFixedPointMatchesTheorem2) {
  // z ≥ 0, γ = 1 (s = 2), μ = -0.5.
  const ScalarPrior hs = ScalarPrior::AtLeast(0.0, 2.0);
  EXPECT_NEAR(NupFixedPoint(hs, 2.0, -0.5, 0.2, 20000), -0.1, 1e-8);
  EXPECT_NEAR(NupFixedPoint(hs, 2.0, -0.5, 0.3125, 20000), 0.0, 1e-8);
  EXPECT_NEAR(Decide(hs, 2.0, {-0.5, 0.2}).z, -0.1, 1e-15);
  EXPECT_DOUBLE_EQ(Decide(hs, 2.0, {-0.5, 0.3125}).z, 0.0);
}

TEST(NupUpdate, BoxProductFormsHaveNoZeroOverZeroAtTheBounds) {
  const ScalarPrior box = ScalarPrior::Box(-1.0, 2.0, 3.0);
  for (double x : {-1.0, 2.0}) {
    const ScalarFactor f = NupUpdate(box, 3.0, x);
    EXPECT_EQ(f.V, 0.0);
    EXPECT_EQ(f.m, x);
  }
  const ScalarFactor inside = NupUpdate(box, 3.0, 0.5);
  EXPECT_DOUBLE_EQ(inside.m, 0.5);  // inside the box: no pull
  EXPECT_GT(inside.V, 0.0);
  // Outside, the mean is reflected to the feasible side.
  EXPECT_DOUBLE_EQ(NupUpdate(ScalarPrior::AtLeast(1.0, 2.0), 2.0, -1.0).m, 3.0);
  EXPECT_DOUBLE_EQ(NupUpdate(ScalarPrior::AtMost(1.0, 2.0), 2.0, 4.0).m, -2.0);
}

// Brute force prox: minimise cost(z) + (z-m)²/(2V) by a grid and golden-section refinement.
double BruteForceProx(const ScalarPrior& prior, double m, double V) {
  const auto f = [&](double z) { return PriorCost(prior, z) + (z - m) * (z - m) / (2 * V); };
  double lo = m - 50.0, hi = m + 50.0, best = lo;
  const int grid = 200000;
  for (int i = 0; i <= grid; ++i) {
    const double z = lo + (hi - lo) * i / grid;
    if (f(z) < f(best)) best = z;
  }
  double a = best - (hi - lo) / grid, b = best + (hi - lo) / grid;
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  for (int i = 0; i < 200; ++i) {
    const double c = b - g * (b - a), d = a + g * (b - a);
    if (f(c) < f(d))
      b = d;
    else
      a = c;
  }
  return 0.5 * (a + b);
}

TEST(DecidingRules, AreProximalOperatorsOfTheirCost) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 3.0), v(0.05, 2.0), s(0.2, 4.0);
  for (int trial = 0; trial < 40; ++trial) {
    const double a = u(rng), width = v(rng), slope = s(rng), m = 2 * u(rng), V = v(rng);
    const ScalarPrior priors[] = {
        ScalarPrior::L1(a, slope),
        ScalarPrior::Huber(a, std::sqrt(width), slope),
        ScalarPrior::AtLeast(a, slope),
        ScalarPrior::AtMost(a, slope),
        ScalarPrior::Box(a, a + width, slope),
        ScalarPrior::Box(a, a + width, slope).WithGaussian(u(rng), v(rng)),
        ScalarPrior::Gaussian(a, width),
    };
    for (const ScalarPrior& prior : priors) {
      const double z = Decide(prior, prior.slope, {m, V}).z;
      EXPECT_NEAR(z, BruteForceProx(prior, m, V), 1e-6)
          << PriorKindName(prior.kind) << " a=" << a << " m=" << m << " V=" << V << " s=" << slope;
    }
  }
}

TEST(DecidingRules, HardConstraintsProject) {
  const ScalarPrior box = ScalarPrior::Box(-1.0, 1.0);
  EXPECT_EQ(Decide(box, kInfinity, {5.0, 1e3}).z, 1.0);
  EXPECT_EQ(Decide(box, kInfinity, {-5.0, 1e-3}).z, -1.0);
  EXPECT_EQ(Decide(box, kInfinity, {0.25, 1.0}).z, 0.25);
  EXPECT_EQ(Decide(box, kInfinity, {5.0, 1.0}).region, Region::kAtUpper);
  // With a Gaussian part: combine, then clip (§5.3).
  const ScalarPrior boxg = box.WithGaussian(3.0, 1.0);
  EXPECT_DOUBLE_EQ(Decide(boxg, kInfinity, {0.0, 1.0}).z, 1.0);
  EXPECT_DOUBLE_EQ(Decide(boxg, kInfinity, {0.0, 0.25}).z, 0.6);
}

TEST(DualNup, HardHalfSpaceIsAGaussianAtHalfGammaInside) {
  // y ≥ a: mean a + γ/2, precision 2|ỹ|/γ (§9.4 table).
  const ScalarFactor f = DualNupFactor(ScalarPrior::AtLeast(1.0), -0.3, 0.5);
  EXPECT_NEAR(f.w, 2 * 0.3 / 0.5, 1e-15);
  EXPECT_NEAR(f.xi / f.w, 1.0 + 0.25, 1e-15);
  // An inactive constraint has no factor; a saturated soft dual is a pure linear term.
  EXPECT_TRUE(DualNupFactor(ScalarPrior::Box(0.0, 1.0), 0.0, 0.5).empty());
  const ScalarFactor sat = DualNupFactor(ScalarPrior::AtLeast(1.0, 2.0), -2.0, 0.5);
  EXPECT_EQ(sat.w, 0.0);
  EXPECT_NEAR(sat.xi, 2.0, 1e-15);
}

TEST(AdaptiveSlope, RequiredSlopeMakesTheDecisionFeasible) {
  const ScalarPrior box = ScalarPrior::Box(-1.0, 1.0, 10.0);
  const Message msg{4.0, 0.1};  // with s = 10: 4 - 10·0.1 = 3 > 1, infeasible
  EXPECT_GT(Decide(box, 10.0, msg).z, 1.0);
  const double s = RequiredSlope(box, msg);
  EXPECT_NEAR(s, 30.0, 1e-12);
  EXPECT_NEAR(Decide(box, s, msg).z, 1.0, 1e-12);
}

TEST(PolishRegions, ABoxPinnedAtOneBoundIsReleasedBeforeItCrosses) {
  const ScalarPrior box = ScalarPrior::Box(-0.5, 0.5);
  EXPECT_EQ(NextPolishRegion(box, Region::kAtLower, Region::kAtUpper), Region::kInside);
  EXPECT_EQ(NextPolishRegion(box, Region::kAtUpper, Region::kAtLower), Region::kInside);
  // Soft boxes: the linear pieces beyond the kinks count as their side.
  const ScalarPrior soft = ScalarPrior::Box(-0.5, 0.5, 3.0);
  EXPECT_EQ(NextPolishRegion(soft, Region::kBelow, Region::kAbove), Region::kInside);
  EXPECT_EQ(NextPolishRegion(soft, Region::kAtUpper, Region::kBelow), Region::kInside);
  // Every other transition is the plain primal-dual active-set step.
  EXPECT_EQ(NextPolishRegion(box, Region::kAtLower, Region::kInside), Region::kInside);
  EXPECT_EQ(NextPolishRegion(box, Region::kInside, Region::kAtUpper), Region::kAtUpper);
  EXPECT_EQ(NextPolishRegion(soft, Region::kAtLower, Region::kBelow), Region::kBelow);
  // Other kinds have no opposite bound to jump to.
  const ScalarPrior l1 = ScalarPrior::L1(0.0, 1.0);
  EXPECT_EQ(NextPolishRegion(l1, Region::kBelow, Region::kAbove), Region::kAbove);
  const ScalarPrior hinge = ScalarPrior::AtLeast(0.0);
  EXPECT_EQ(NextPolishRegion(hinge, Region::kAtLower, Region::kInside), Region::kInside);
}

}  // namespace
}  // namespace nupmpc::core
