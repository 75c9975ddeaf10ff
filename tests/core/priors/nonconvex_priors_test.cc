// Non-convex priors (nup-algorithms.md §5.1, §5.2, §7): the scalar rules against their
// closed forms, and binary control through IAKE against exhaustive search (the DAC
// example of [KL] §V-A with the short-horizon set-up of §7.3).
#include <cmath>
#include <vector>

#include "core/examples/scenarios/dac.h"
#include "core/priors/scalar_rules.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

// One step of the scalar alternation of §5.2: the NUP factor at x and a Gaussian
// observation N(mu, s2) give the next estimate (and its posterior variance).
struct Scalar {
  double x, vp;
};
Scalar Alternate(const ScalarPrior& prior, Scalar at, double mu, double s2) {
  const ScalarFactor f = NupUpdate(prior, prior.slope, at.x, at.vp);
  if (f.V == 0.0) return {f.m, 0.0};
  const double w = 1.0 / f.V + 1.0 / s2;
  return {(f.m / f.V + mu / s2) / w, 1.0 / w};
}

double Distance(const ScalarPrior& binary, double x) { return HardViolation(binary, x); }

// Roots in (0, 1) of the AM fixed-point cubic -x³ + (1+μ)x² - (μ+2s²)x + s² (§5.2).
std::vector<double> CubicRootsInUnitInterval(double mu, double s2) {
  const auto f = [&](double x) { return -x * x * x + (1 + mu) * x * x - (mu + 2 * s2) * x + s2; };
  std::vector<double> roots;
  const int grid = 200000;
  for (int i = 1; i < grid - 1; ++i) {
    double lo = static_cast<double>(i) / grid, hi = static_cast<double>(i + 1) / grid;
    if (f(lo) * f(hi) > 0.0) continue;
    for (int k = 0; k < 80; ++k) {
      const double mid = 0.5 * (lo + hi);
      (f(lo) * f(mid) <= 0.0 ? hi : lo) = mid;
    }
    roots.push_back(0.5 * (lo + hi));
  }
  return roots;
}

TEST(BinaryPrior, AmFixedPointsAreTheRootsOfThePapersCubicAndVanishAtTheThreshold) {
  const ScalarPrior am = ScalarPrior::Binary(0.0, 1.0, /*em=*/false);
  const double mu = 0.3;
  // Below s²_AM = 0.02779 the cubic has three roots in (0, 1), above it one.
  EXPECT_EQ(CubicRootsInUnitInterval(mu, 0.0277).size(), 3u);
  EXPECT_EQ(CubicRootsInUnitInterval(mu, 0.0279).size(), 1u);
  for (const double s2 : {0.02, 0.0277, 0.0279, 0.05}) {
    for (const double root : CubicRootsInUnitInterval(mu, s2)) {
      const Scalar next = Alternate(am, {root, 0.0}, mu, s2);
      EXPECT_NEAR(next.x, root, 1e-9) << "s2 = " << s2;  // NupUpdate's binary rule has these fixed points
    }
  }
}

TEST(BinaryPrior, AmReachesALevelFastAndEmOnlySublinearly) {
  // §5.2: at s² = 0.3 AM lands exactly on a level in a few dozen iterations; EM is still
  // visibly away after a thousand (it needs an iteration budget and final rounding).
  const double mu = 0.3, s2 = 0.3;
  Scalar am{0.5, 1.0}, em{0.5, 1.0};
  int am_iterations = 0;
  for (; am_iterations < 100 && Distance(ScalarPrior::Binary(0, 1), am.x) > 1e-12; ++am_iterations) {
    am = Alternate(ScalarPrior::Binary(0.0, 1.0, false), am, mu, s2);
  }
  EXPECT_LT(am_iterations, 100);
  for (int i = 0; i < 1000; ++i) em = Alternate(ScalarPrior::Binary(0.0, 1.0, true), em, mu, s2);
  EXPECT_GT(Distance(ScalarPrior::Binary(0, 1), em.x), 1e-7);
  EXPECT_LT(Distance(ScalarPrior::Binary(0, 1), em.x), 0.05);  // but it does approach a level
}

TEST(LpPrior, WithExponentOneItIsTheL1SoftThreshold) {
  const double mu = 0.8, s2 = 0.5, slope = 1.0;
  Scalar lp{mu, 0.0};
  for (int i = 0; i < 2000; ++i) lp = Alternate(ScalarPrior::Lp(0.0, 1.0, slope), lp, mu, s2);
  const Decision l1 = Decide(ScalarPrior::L1(0.0, slope), slope, {mu, s2});
  EXPECT_NEAR(lp.x, l1.z, 1e-6);  // prox of s|z| at (0.8, 0.5): 0.8 - 0.5 = 0.3
}

TEST(LpPrior, HalfPowerGivesExactZerosOrAStationaryPoint) {
  const double s2 = 0.5, slope = 1.0, p = 0.5;
  const ScalarPrior prior = ScalarPrior::Lp(0.0, p, slope);
  // Small data: the estimate collapses to the centre (sparsity).
  Scalar small{0.2, 0.0};
  for (int i = 0; i < 200; ++i) small = Alternate(prior, small, 0.2, s2);
  EXPECT_LT(std::abs(small.x), 1e-8);
  // Large data: a stationary point of s|z|^p + (z - μ)²/(2s²).
  const double mu = 3.0;
  Scalar large{mu, 0.0};
  for (int i = 0; i < 2000; ++i) large = Alternate(prior, large, mu, s2);
  const double gradient = slope * p * std::pow(large.x, p - 1.0) + (large.x - mu) / s2;
  EXPECT_NEAR(gradient, 0.0, 1e-8);
  EXPECT_GT(large.x, 2.0);
}

TEST(NonconvexPriors, AreValidatedNamingTheField) {
  Problem p = Problem::TimeInvariant(1, 1, 1, 3);
  p.A[0] << 1.0;
  p.B[0] << 1.0;
  p.C[0] << 1.0;
  p.initial_mean = Eigen::VectorXd::Zero(1);
  p.input_priors.assign(3, ScalarPrior::Binary(1.0, 0.0));
  EXPECT_THAT(Validate(p), testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("lower")));
  p.input_priors.assign(3, ScalarPrior::Lp(0.0, 1.5, 1.0));
  EXPECT_THAT(Validate(p), testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("exponent")));
  p.input_priors.assign(3, ScalarPrior::SmoothedNuv(0.0, -1.0));
  EXPECT_THAT(Validate(p), testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("radius")));
  p.input_priors.assign(3, ScalarPrior::PlainNuv(0.0));
  EXPECT_THAT(Validate(p), testing::IsOk());
  // Only IAKE runs them.
  SolverOptions options;
  options.algorithm = Algorithm::kIbffd;
  EXPECT_THAT(Session::Create(p, options).status(),
              testing::StatusIs(absl::StatusCode::kFailedPrecondition, ::testing::HasSubstr("input_priors[0]")));
  auto session = Session::Create(p);
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_EQ((*session)->algorithm(), Algorithm::kIake);
}

TEST(BinaryControl, ShortHorizonIakeIsWithinAFewPercentOfExhaustiveSearch) {
  // §7.3: receding horizon K = 8, V_Y = 0.01; each step applies the first input of the
  // window's plan. IAKE-EM (300 iterations, cold, rounded) vs all 256 binary sequences.
  auto run = examples::DacOnline(/*window=*/8, /*steps=*/150, /*output_variance=*/0.01, /*frequency_hz=*/2.0,
                                 /*iterations=*/300);
  ASSERT_TRUE(run.ok()) << run.status();
  for (int t = 0; t < run->nup_inputs.size(); ++t) {
    ASSERT_TRUE(run->nup_inputs(t) == 0.0 || run->nup_inputs(t) == 1.0) << t;
  }
  RecordProperty("mse_iake", std::to_string(run->nup_mse));
  RecordProperty("mse_exhaustive", std::to_string(run->exhaustive_mse));
  std::printf("DAC K=8: MSE IAKE-EM %.4e vs exhaustive %.4e (ratio %.3f), largest pre-rounding gap %.3g\n",
              run->nup_mse, run->exhaustive_mse, run->nup_mse / run->exhaustive_mse, run->largest_gap);
  EXPECT_LE(run->nup_mse, 1.10 * run->exhaustive_mse);
  EXPECT_GT(run->largest_gap, 0.0);  // EM had not binarised everything: rounding mattered
}

}  // namespace
}  // namespace nupmpc::core
