// How a solve with binary inputs ends (SolverOptions.discrete_*): the binary NUP update
// clamps its estimate to the hull of the levels, the plan is made discrete block by block
// with re-solves, then improved by a local search. Checked against independent
// simulations of the plant and against the plain rounding of §7.2.
#include <algorithm>
#include <cmath>
#include <vector>

#include "core/examples/scenarios/corridor.h"
#include "core/examples/scenarios/dac.h"
#include "core/priors/scalar_rules.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

constexpr int kSteps = 60;
constexpr double kOutputVariance = 0.01;

// Σ (y[n] - target[n])² over n = 0..K of the DAC plant driven by `u`, simulated here.
double TrackingError(const Problem& p, const Eigen::VectorXd& u) {
  Eigen::VectorXd x = p.initial_mean;
  double sum = 0.0;
  for (int n = 0; n <= p.horizon; ++n) {
    const double y = (p.C[0] * x)(0);
    sum += (y - p.output_priors[n].mean) * (y - p.output_priors[n].mean);
    if (n < p.horizon) x = p.A[0] * x + p.B[0] * u(n);
  }
  return sum;
}

Eigen::VectorXd SolveInputs(const Problem& p, const SolverOptions& options, SolveSummary* summary = nullptr) {
  auto session = Session::Create(p, options);
  EXPECT_TRUE(session.ok()) << session.status();
  Solution plan;
  auto solved = (*session)->Solve(&plan);
  EXPECT_TRUE(solved.ok()) << solved.status();
  if (summary != nullptr) *summary = *solved;
  return plan.inputs.col(0);
}

bool AllBinary(const Eigen::VectorXd& u) { return (u.array() == 0.0 || u.array() == 1.0).all(); }

TEST(BinaryNupUpdate, ClampsTheEstimateToTheLevelsHull) {
  // Outside [a, b] the EM binary factor would widen with the distance (V ≈ x²/2) and let
  // the scalar run away under a strong pull; clamped, it is the factor at the nearer level.
  const ScalarPrior binary = ScalarPrior::Binary(0.0, 1.0);
  for (const double vp : {0.0, 0.05}) {
    const ScalarFactor below = NupUpdate(binary, 1.0, -600.0, vp), at_lower = NupUpdate(binary, 1.0, 0.0, vp);
    const ScalarFactor above = NupUpdate(binary, 1.0, 7.5, vp), at_upper = NupUpdate(binary, 1.0, 1.0, vp);
    EXPECT_EQ(below.m, at_lower.m);
    EXPECT_EQ(below.V, at_lower.V);
    EXPECT_EQ(above.m, at_upper.m);
    EXPECT_EQ(above.V, at_upper.V);
    EXPECT_LE(below.V, vp + 0.5);
  }
  // Inside, unchanged: the §5.1 formula.
  const double x = 0.3, vp = 0.02, sa = vp + x * x, sb = vp + (x - 1) * (x - 1);
  const ScalarFactor inside = NupUpdate(binary, 1.0, x, vp);
  EXPECT_DOUBLE_EQ(inside.V, sa * sb / (sa + sb));
  EXPECT_DOUBLE_EQ(inside.m, sa / (sa + sb));
}

TEST(DiscretePlan, NoSingleOrNeighbourMoveImprovesTheSearchedPlan) {
  const Problem p = examples::DacWindow(kSteps, kOutputVariance, 0, 2.0);
  SolverOptions options;
  options.max_iterations = 300;
  SolveSummary summary;
  Eigen::VectorXd u = SolveInputs(p, options, &summary);
  ASSERT_TRUE(AllBinary(u));
  EXPECT_TRUE(summary.rounded);
  // J of the session is the Gaussian tracking cost: Σ(y - target)²/(2 V_Y) (+ nothing else).
  const double error = TrackingError(p, u);
  EXPECT_NEAR(summary.objective, error / (2 * kOutputVariance), 1e-9 * summary.objective);
  // The search stopped in a local optimum of its neighbourhood, checked by simulation:
  // flipping one input, or moving a 1 to the next step (or back), does not help.
  for (int n = 0; n < kSteps; ++n) {
    Eigen::VectorXd flipped = u;
    flipped(n) = 1.0 - u(n);
    EXPECT_GE(TrackingError(p, flipped), error * (1 - 1e-12)) << "flip " << n;
    if (n + 1 < kSteps && u(n) != u(n + 1)) {
      Eigen::VectorXd swapped = u;
      std::swap(swapped(n), swapped(n + 1));
      EXPECT_GE(TrackingError(p, swapped), error * (1 - 1e-12)) << "swap " << n;
    }
  }
}

// Largest distance of the plan's output 0 outside the corridor, over steps 1..K.
double CorridorViolation(const Solution& plan) {
  double worst = 0.0;
  for (int n = 1; n <= examples::kCorridorSteps; ++n) {
    worst = std::max(worst, std::abs(plan.outputs(n, 0) - examples::CorridorTarget(n)) - examples::kCorridorHalfWidth);
  }
  return worst;
}

TEST(DiscretePlan, FixingKeepsAnIntegratorsPlanInItsCorridor) {
  // The three-level corridor ([KL] §V-B version 4, a triple integrator): the same EM run,
  // made discrete by plain rounding (both phases off), by fixing alone, and by fixing plus
  // search (the defaults). Rounded at once, the small errors of the early inputs grow
  // along the horizon.
  auto problem = examples::CorridorProblem(examples::CorridorVersion::kThreeLevels);
  ASSERT_TRUE(problem.ok()) << problem.status();
  SolverOptions plain;
  plain.max_iterations = 3000;
  plain.discrete_fixing_passes = 0;
  plain.discrete_search_sweeps = 0;
  SolverOptions fixed = plain;
  fixed.discrete_fixing_passes = SolverOptions{}.discrete_fixing_passes;
  SolverOptions searched = fixed;
  searched.discrete_search_sweeps = SolverOptions{}.discrete_search_sweeps;
  double violation[3];
  int k = 0;
  for (const SolverOptions& options : {plain, fixed, searched}) {
    auto session = Session::Create(*problem, options);
    ASSERT_TRUE(session.ok()) << session.status();
    Solution plan;
    auto solved = (*session)->Solve(&plan);
    ASSERT_TRUE(solved.ok()) << solved.status();
    ASSERT_TRUE((plan.inputs.array() == 0.0 || plan.inputs.array() == 1.0).all());  // the expanded binaries
    violation[k++] = CorridorViolation(plan);
  }
  std::printf("three-level corridor, max violation: plain rounding %.3g, fixing %.3g, fixing + search %.3g\n",
              violation[0], violation[1], violation[2]);
  EXPECT_GT(violation[0], 1.0);
  EXPECT_LT(violation[1], 0.2 * violation[0]);
  EXPECT_LE(violation[2], 1e-9);
}

TEST(DiscretePlan, TheSearchImprovesTheLongDacPlan) {
  const Problem p = examples::DacWindow(300, kOutputVariance, 0, 2.0);
  SolverOptions fixed;
  fixed.max_iterations = 1000;
  fixed.discrete_search_sweeps = 0;
  SolverOptions searched = fixed;
  searched.discrete_search_sweeps = SolverOptions{}.discrete_search_sweeps;
  SolveSummary s_fixed, s_searched;
  const Eigen::VectorXd u_fixed = SolveInputs(p, fixed, &s_fixed);
  const Eigen::VectorXd u_searched = SolveInputs(p, searched, &s_searched);
  ASSERT_TRUE(AllBinary(u_fixed) && AllBinary(u_searched));
  // 30 blocks, discrete_fixing_passes after each but the last.
  EXPECT_EQ(s_fixed.iterations, 1000 + 29 * fixed.discrete_fixing_passes);
  EXPECT_EQ(s_fixed.discrete_moves, 0);
  EXPECT_GT(s_searched.discrete_moves, 0);
  const double e_fixed = TrackingError(p, u_fixed), e_searched = TrackingError(p, u_searched);
  std::printf("DAC K=300 tracking error: without search %.4g, with search %.4g (%d moves)\n", e_fixed, e_searched,
              s_searched.discrete_moves);
  EXPECT_LT(e_searched, 0.9 * e_fixed);
}

// The best tracking error among the plans two flap moves away from `u`: two ones, each
// moved to a neighbouring zero, searched exhaustively here with the test's own simulation.
double BestPairMoveError(const Problem& p, const Eigen::VectorXd& u) {
  const int N = static_cast<int>(u.size());
  double best = INFINITY;
  Eigen::VectorXd trial = u;
  const auto move = [&](int from, int to) {
    if (to < 0 || to >= N || trial(from) != 1.0 || trial(to) != 0.0) return false;
    std::swap(trial(from), trial(to));
    return true;
  };
  for (int n1 = 0; n1 < N; ++n1) {
    for (int n2 = n1 + 1; n2 < N; ++n2) {
      for (const int d1 : {-1, 1}) {
        for (const int d2 : {-1, 1}) {
          trial = u;
          if (move(n1, n1 + d1) && move(n2, n2 + d2)) best = std::min(best, TrackingError(p, trial));
        }
      }
    }
  }
  return best;
}

TEST(DiscretePlan, NoPairOfFlapMovesImprovesTheSearchedPlan) {
  // The search ends where no two levels moved at once (within the reach, here the whole
  // horizon) lower J; J of a Gaussian-tracking DAC plan is its tracking error over 2V_Y.
  const Problem p = examples::DacWindow(kSteps, kOutputVariance, 0, 2.0);
  SolverOptions options;
  options.max_iterations = 300;
  options.discrete_pair_reach = kSteps;
  const Eigen::VectorXd u = SolveInputs(p, options);
  ASSERT_TRUE(AllBinary(u));
  const double error = TrackingError(p, u);
  EXPECT_GE(BestPairMoveError(p, u), error * (1.0 - 1e-12));
  // Without pair moves the same solve stops at a plan that a pair move improves.
  options.discrete_pair_reach = 0;
  const Eigen::VectorXd single = SolveInputs(p, options);
  ASSERT_TRUE(AllBinary(single));
  std::printf("DAC K=%d tracking error: single moves %.6g (best pair move from it %.6g), with pair moves %.6g\n",
              kSteps, TrackingError(p, single), BestPairMoveError(p, single), error);
  EXPECT_LT(BestPairMoveError(p, single), TrackingError(p, single) * (1.0 - 1e-9));
  EXPECT_LE(error, TrackingError(p, single));
}

TEST(DiscretePlan, PinsDoNotOutliveTheSolve) {
  // A second cold solve on the same session equals a fresh session's solve: the pins of
  // the first solve's fixing phase were released.
  const Problem p = examples::DacWindow(kSteps, kOutputVariance, 0, 2.0);
  SolverOptions options;
  options.max_iterations = 200;
  auto session = Session::Create(p, options);
  ASSERT_TRUE(session.ok());
  SolveLimits cold;
  cold.warm_start = false;
  Solution first, second;
  ASSERT_TRUE((*session)->Solve(cold, &first).ok());
  ASSERT_TRUE((*session)->Solve(cold, &second).ok());
  EXPECT_EQ(first.inputs, second.inputs);
  EXPECT_EQ(SolveInputs(p, options), Eigen::VectorXd(second.inputs.col(0)));
}

TEST(DiscretePlan, ATimeLimitStillGivesADiscretePlan) {
  const Problem p = examples::DacWindow(300, kOutputVariance, 0, 2.0);
  SolverOptions options;
  options.max_iterations = 100000;
  auto session = Session::Create(p, options);
  ASSERT_TRUE(session.ok());
  SolveLimits limits;
  limits.time_limit_seconds = 0.02;
  Solution plan;
  auto solved = (*session)->Solve(limits, &plan);
  ASSERT_TRUE(solved.ok());
  EXPECT_EQ(solved->status, SolveStatus::kTimeLimit);
  EXPECT_TRUE(AllBinary(plan.inputs.col(0)));
  EXPECT_LT(solved->solve_seconds, 0.5);
}

TEST(DiscretePlan, BadOptionsAreRefusedNamingTheField) {
  const Problem p = examples::DacWindow(8, kOutputVariance, 0, 2.0);
  SolverOptions options;
  options.discrete_fixing_passes = -1;
  EXPECT_THAT(Session::Create(p, options).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("discrete_fixing_passes")));
  options = {};
  options.discrete_fixing_blocks = 0;
  EXPECT_THAT(Session::Create(p, options).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("discrete_fixing_blocks")));
  options = {};
  options.discrete_search_sweeps = -2;
  EXPECT_THAT(Session::Create(p, options).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("discrete_search_sweeps")));
  options = {};
  options.discrete_pair_reach = -1;
  EXPECT_THAT(Session::Create(p, options).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("discrete_pair_reach")));
}

}  // namespace
}  // namespace nupmpc::core
