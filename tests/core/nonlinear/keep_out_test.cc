// Keep-out regions by sequential linearisation ([KL] §V-D): the linearised distance is a
// lower bound of the true one (so every linearised plan keeps out), the plans improve
// monotonically and converge to a fixed point, the paper's single-circle problem and a
// scene of several shapes are solved, and bad regions are refused naming the field.
#include "core/nonlinear/keep_out.h"

#include <cmath>
#include <numbers>
#include <random>

#include "core/examples/scenarios/obstacle_avoidance.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

using ::nupmpc::testing::StatusIs;
using ::testing::HasSubstr;

constexpr int kHorizon = 30;

TEST(KeepOutClearance, MatchesClosedForms) {
  const KeepOutRegion circle = KeepOutRegion::Circle({1.0, 2.0}, 0.5);
  EXPECT_NEAR(KeepOutClearance(circle, {4.0, 6.0}), 5.0 - 0.5, 1e-12);  // Euclidean distance
  EXPECT_NEAR(KeepOutClearance(circle, {1.0, 2.0}), -0.5, 1e-12);
  // A rectangle 2 × 1 rotated by 90°: its long side is vertical.
  const KeepOutRegion rect = KeepOutRegion::Rectangle({0.0, 0.0}, 1.0, 0.5, std::numbers::pi / 2);
  EXPECT_NEAR(KeepOutClearance(rect, {0.0, 0.9}), 0.5 * (0.9 - 1.0), 1e-12);  // inside, near the top
  EXPECT_GT(KeepOutClearance(rect, {0.6, 0.0}), 0.0);                         // right of the short side
  EXPECT_LT(KeepOutClearance(rect, {0.4, 0.95}), 0.0);                        // inside, near a corner
}

// z = C_row x + d of the linearised problem never exceeds the true f(y) = ρ‖w‖, at any
// point y, whatever the linearisation point: the property that keeps linearised plans out.
TEST(KeepOutLinearisation, IsALowerBoundOfTheDistanceEverywhere) {
  Problem plant = examples::ObstaclePlant(2);
  KeepOut keep_out;
  keep_out.regions = {KeepOutRegion::Ellipse({1.0, 0.5}, 0.8, 0.3, 0.7),
                      KeepOutRegion::Rectangle({-0.5, 1.0}, 0.4, 0.9, -0.3)};
  auto linearisation = MakeKeepOutLinearisation(plant, keep_out);
  ASSERT_TRUE(linearisation.ok()) << linearisation.status();
  Problem linearised = (*linearisation)->shape();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coordinate(-2.0, 2.5);
  const auto state_at = [](double p1, double p2) { return Eigen::Vector4d(0.3, p1, -0.2, p2); };
  for (int trial = 0; trial < 200; ++trial) {
    Solution point;
    point.inputs = Eigen::MatrixXd::Zero(2, 2);
    point.states.resize(3, 4);
    for (int n = 0; n < 3; ++n) point.states.row(n) = state_at(coordinate(rng), coordinate(rng)).transpose();
    (*linearisation)->Linearise(point, &linearised);
    for (int probe = 0; probe < 20; ++probe) {
      const Eigen::Vector2d y(coordinate(rng), coordinate(rng));
      for (int r = 0; r < 2; ++r) {
        const double z = linearised.C[1].row(2 + r).dot(state_at(y(0), y(1))) + linearised.output_offset[1](2 + r);
        const KeepOutRegion& region = keep_out.regions[r];
        // True f from the clearance, with the rectangle's superellipse norm bounded by
        // its ∞-norm times 2^{1/p} (what the threshold allows for).
        const double rho = region.half_axes.minCoeff();
        const double f_upper = region.shape == KeepOutShape::kRectangle
                                   ? (KeepOutClearance(region, y) + rho) * std::pow(2.0, 1.0 / keep_out.rectangle_order)
                                   : KeepOutClearance(region, y) + rho;
        EXPECT_LE(z, f_upper + 1e-12) << "trial " << trial << " region " << r;
        // The threshold test is exact for the shape: z ≥ threshold implies outside.
        if (z >= linearised.output_prior(1, 2 + r).lower) {
          EXPECT_GE(KeepOutClearance(region, y), -1e-12);
        }
      }
    }
  }
}

TEST(KeepOut, PaperSingleCircleReachesTheGoalAroundTheObstacle) {
  auto run = examples::PlanAroundObstacles(kHorizon, examples::SingleCircleScene(kInfinity));
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_TRUE(run->summary.converged);
  EXPECT_GE(run->min_clearance, -1e-9);
  EXPECT_LE(run->summary.nonlinear_violation, 1e-9);
  EXPECT_LT(run->goal_error, 1e-6);
  // The plan really goes round: the straight line it started from runs through the
  // centre; the plan leaves the diagonal by most of the radius (not all: the constraint
  // holds at the samples, and the chord between two samples may cut the rim).
  const Eigen::ArrayXd off_diagonal = (run->positions.col(0) - run->positions.col(1)).array().abs() / std::sqrt(2.0);
  EXPECT_GE(off_diagonal.maxCoeff(), 0.7);
}

TEST(KeepOut, PaperSlopeFiveIsExactHereAndATinySlopeIsNot) {
  // γ = 5 ([KL]) exceeds the constraint's multiplier on this problem: same plan as hard.
  auto soft = examples::PlanAroundObstacles(kHorizon, examples::SingleCircleScene(5.0));
  auto hard = examples::PlanAroundObstacles(kHorizon, examples::SingleCircleScene(kInfinity));
  ASSERT_TRUE(soft.ok() && hard.ok());
  EXPECT_GE(soft->min_clearance, -1e-9);
  EXPECT_LT((soft->positions - hard->positions).cwiseAbs().maxCoeff(), 1e-6);
  // A slope far below the multiplier buys a shortcut through the obstacle.
  auto weak = examples::PlanAroundObstacles(kHorizon, examples::SingleCircleScene(0.01));
  ASSERT_TRUE(weak.ok()) << weak.status();
  EXPECT_LT(weak->min_clearance, -0.05);
}

// Every linearised plan is feasible (inner approximation) and none is worse than the one
// before (the convex-concave procedure's descent): run 1, 2, … linearisations.
TEST(KeepOut, EveryLinearisationKeepsOutAndTheObjectiveNeverIncreases) {
  double previous = kInfinity;
  for (int k = 1; k <= 6; ++k) {
    SequentialOptions options;
    options.max_linearisations = k;
    auto run = examples::PlanAroundObstacles(kHorizon, examples::MixedShapesScene(kInfinity), options);
    ASSERT_TRUE(run.ok()) << run.status();
    EXPECT_GE(run->min_clearance, -1e-9) << k << " linearisations";
    EXPECT_LE(run->summary.last_inner.objective, previous * (1 + 1e-9)) << k << " linearisations";
    previous = run->summary.last_inner.objective;
  }
}

TEST(KeepOut, MixedShapesSceneIsSolved) {
  auto run = examples::PlanAroundObstacles(kHorizon, examples::MixedShapesScene(kInfinity));
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_TRUE(run->summary.converged);
  EXPECT_GE(run->min_clearance, -1e-9);
  EXPECT_LT(run->goal_error, 1e-6);
  // A converged plan is a fixed point: relinearising around it changes nothing.
  EXPECT_LE(run->summary.last_step, 1e-6);
}

TEST(KeepOut, BadRegionsAreRefusedNamingTheField) {
  const Problem plant = examples::ObstaclePlant(5);
  KeepOut k;
  k.regions = {KeepOutRegion::Circle({0.0, 0.0}, -1.0)};
  EXPECT_THAT(MakeKeepOutLinearisation(plant, k).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("keep_out.regions[0].half_axes")));
  k.regions = {KeepOutRegion::Circle({NAN, 0.0}, 1.0)};
  EXPECT_THAT(MakeKeepOutLinearisation(plant, k).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("keep_out.regions[0].centre")));
  k.regions = {KeepOutRegion::Circle({0.0, 0.0}, 1.0, 0.0)};
  EXPECT_THAT(MakeKeepOutLinearisation(plant, k).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("keep_out.regions[0].slope")));
  k.regions = {KeepOutRegion::Circle({0.0, 0.0}, 1.0)};
  k.second_output = 2;
  EXPECT_THAT(MakeKeepOutLinearisation(plant, k).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("keep_out.second_output")));
  k.second_output = 0;
  EXPECT_THAT(MakeKeepOutLinearisation(plant, k).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("must differ")));
}

}  // namespace
}  // namespace nupmpc::core
