// Non-convex priors (nup-algorithms.md §5.1, §5.2, §7): the scalar rules against their
// closed forms, and binary control through IAKE against exhaustive search (the DAC
// example of [KL] §V-A with the short-horizon set-up of §7.3).
#include <cmath>
#include <vector>

#include "core/priors/scalar_rules.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/dac_plant.h"
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

Problem DacWindow(int K, double output_variance) {
  Problem p = testing::DacPlant(K);
  p.input_priors.assign(K, ScalarPrior::Binary(0.0, 1.0, /*em=*/true));
  p.output_priors.assign(K + 1, ScalarPrior::Gaussian(0.0, output_variance));
  return p;
}

using testing::DacTarget;

TEST(BinaryControl, ShortHorizonIakeIsWithinAFewPercentOfExhaustiveSearch) {
  // §7.3: receding horizon K = 8, V_Y = 0.01; each step applies the first input of the
  // window's plan. IAKE-EM (300 iterations, rounded) vs all 256 binary sequences.
  const int K = 8, steps = 150;
  const double VY = 0.01;
  Problem window = DacWindow(K, VY);
  const Eigen::Matrix3d A = window.A[0];
  const Eigen::Vector3d B = window.B[0];
  const Eigen::RowVector3d C = window.C[0];
  SolverOptions options;
  options.max_iterations = 300;  // a budget (§7.2): EM stops early only once every input is binary
  auto session = Session::Create(window, options);
  ASSERT_TRUE(session.ok()) << session.status();

  Eigen::Vector3d x_nup = window.initial_mean, x_exh = window.initial_mean;
  double sse_nup = 0.0, sse_exh = 0.0, largest_gap = 0.0;
  Solution plan;
  for (int t = 0; t < steps; ++t) {
    for (int n = 0; n <= K; ++n) window.output_priors[n] = ScalarPrior::Gaussian(DacTarget(t + n), VY);
    window.initial_mean = x_nup;
    ASSERT_THAT((*session)->Update(window), testing::IsOk());
    SolveLimits cold;
    cold.warm_start = false;
    auto summary = (*session)->Solve(cold, &plan);
    ASSERT_TRUE(summary.ok()) << summary.status();
    ASSERT_TRUE(summary->rounded);
    largest_gap = std::max(largest_gap, summary->discrete_gap);
    for (int n = 0; n < K; ++n) ASSERT_TRUE(plan.inputs(n, 0) == 0.0 || plan.inputs(n, 0) == 1.0);

    // Exhaustive search over the window from the exhaustive controller's own state.
    double best_cost = INFINITY;
    double best_u0 = 0.0;
    for (int code = 0; code < (1 << K); ++code) {
      Eigen::Vector3d x = x_exh;
      double cost = 0.0;
      for (int n = 0; n < K; ++n) {
        x = A * x + B * ((code >> n) & 1);
        const double e = C * x - DacTarget(t + n + 1);
        cost += e * e;
      }
      if (cost < best_cost) {
        best_cost = cost;
        best_u0 = code & 1;
      }
    }
    x_nup = A * x_nup + B * plan.inputs(0, 0);
    x_exh = A * x_exh + B * best_u0;
    sse_nup += std::pow(C * x_nup - DacTarget(t + 1), 2);
    sse_exh += std::pow(C * x_exh - DacTarget(t + 1), 2);
  }
  const double mse_nup = sse_nup / steps, mse_exh = sse_exh / steps;
  RecordProperty("mse_iake", std::to_string(mse_nup));
  RecordProperty("mse_exhaustive", std::to_string(mse_exh));
  std::printf("DAC K=8: MSE IAKE-EM %.4e vs exhaustive %.4e (ratio %.3f), largest pre-rounding gap %.3g\n", mse_nup,
              mse_exh, mse_nup / mse_exh, largest_gap);
  EXPECT_LE(mse_nup, 1.10 * mse_exh);
  EXPECT_GT(largest_gap, 0.0);  // EM had not binarised everything: rounding mattered
}

}  // namespace
}  // namespace nupmpc::core
