// Infeasibility detection (core/session/infeasibility.h): a problem whose bounds cannot
// all be met ends with status infeasible, far below the iteration cap, with a finite plan
// (the iterate closest to the bounds) whose violation is at least the distance any plan
// must keep; feasible tight problems converge as before; the detector's two regimes on
// synthetic pass sequences; the session solves a feasible state afterwards like a fresh one.
#include "core/session/infeasibility.h"

#include <cmath>
#include <memory>

#include "core/session/session.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"
#include "tests/util/benchmark_files.h"
#include "tests/util/bounded_integrator.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

constexpr int kHorizon = 20;
constexpr double kInputLimit = 0.1;
constexpr int kCap = 5000;

Problem Integrator(double x0) { return testing::BoundedIntegrator(x0, kHorizon, kInputLimit); }

SolverOptions Capped() {
  SolverOptions options;
  options.max_iterations = kCap;
  return options;
}

void ExpectFinitePlan(const Solution& plan) {
  EXPECT_TRUE(plan.inputs.allFinite());
  EXPECT_TRUE(plan.states.allFinite());
  EXPECT_TRUE(plan.outputs.allFinite());
  EXPECT_GT(plan.inputs.size(), 0);
}

TEST(Infeasibility, OutOfReachIntegratorStatesAreReportedInfeasibleFarBelowTheCap) {
  // From far out (the multipliers explode) to barely out (they creep).
  for (const double x0 : {5.0, 1.2, 1.1001}) {
    SCOPED_TRACE(x0);
    auto session = Session::Create(Integrator(x0), Capped());
    ASSERT_TRUE(session.ok()) << session.status();
    Solution plan;
    auto summary = (*session)->Solve(&plan);
    ASSERT_TRUE(summary.ok());
    EXPECT_EQ(summary->status, SolveStatus::kInfeasible) << summary->Describe();
    EXPECT_EQ(summary->algorithm, Algorithm::kIffbdd);
    EXPECT_LE(summary->iterations, kCap / 20) << summary->Describe();
    EXPECT_TRUE(summary->has_plan);
    ExpectFinitePlan(plan);
    EXPECT_TRUE(std::isfinite(summary->objective));
    // No plan does better than x0 - 1.1, and the returned one is not far off it.
    EXPECT_GE(summary->max_violation, x0 - 1.1 - 1e-12);
    // (IFFBDD's input bounds are constrained rows as well: the iterate may trade an output
    // excess for an input one, and max_violation counts both.)
    EXPECT_LE(summary->max_violation, 2.0 * (x0 - 1.1) + 1e-12);
  }
}

TEST(Infeasibility, FeasibleTightIntegratorStatesStillConverge) {
  for (const double x0 : {1.1, 1.0999, 0.5, 0.0}) {
    SCOPED_TRACE(x0);
    auto session = Session::Create(Integrator(x0), Capped());
    ASSERT_TRUE(session.ok());
    auto summary = (*session)->Solve(nullptr);
    ASSERT_TRUE(summary.ok());
    EXPECT_EQ(summary->status, SolveStatus::kConverged) << summary->Describe();
    EXPECT_LE(summary->max_violation, 1e-9);
  }
}

// The known case: masses_N30 from a state whose velocities carry it through the position
// bound 4 before the inputs (|u| ≤ 0.5) can stop it. Without detection IFFBDD ran to the
// cap with exploding values.
TEST(Infeasibility, MassesFromAStateOutOfReachEndInfeasibleWithFiniteValues) {
  auto inst = bench::LoadBenchmarkInstance(nupmpc::testing::BenchmarkPath("masses_N30"));
  ASSERT_TRUE(inst.ok()) << inst.status();
  Problem p = inst->problem;
  p.initial_mean.setConstant(3.9);
  auto session = Session::Create(p, Capped());
  ASSERT_TRUE(session.ok()) << session.status();
  Solution plan;
  auto summary = (*session)->Solve(&plan);
  ASSERT_TRUE(summary.ok());
  EXPECT_EQ(summary->status, SolveStatus::kInfeasible) << summary->Describe();
  EXPECT_LE(summary->iterations, kCap / 20) << summary->Describe();
  ExpectFinitePlan(plan);
  EXPECT_TRUE(std::isfinite(summary->objective));
  EXPECT_GT(summary->max_violation, 0.0);
  EXPECT_LT(summary->max_violation, 1e3) << "the iterate closest to the bounds, not the diverged last one";

  // The session then solves a feasible state exactly as a fresh session does.
  ASSERT_THAT((*session)->SetInitialState(inst->closed_loop->x1[3]), testing::IsOk());
  Solution again_plan, fresh_plan;
  auto again = (*session)->Solve(&again_plan);
  auto fresh = Session::Create(inst->problem, Capped());
  ASSERT_TRUE(fresh.ok());
  ASSERT_THAT((*fresh)->SetInitialState(inst->closed_loop->x1[3]), testing::IsOk());
  auto reference = (*fresh)->Solve(&fresh_plan);
  ASSERT_TRUE(again.ok() && reference.ok());
  EXPECT_EQ(again->status, SolveStatus::kConverged);
  EXPECT_FALSE(again->warm_started) << "an infeasible solve's multipliers are not carried";
  EXPECT_EQ(again->objective, reference->objective);
  EXPECT_EQ(again_plan.inputs, fresh_plan.inputs);
}

// Not bit for bit: after a warm solve and an infeasible one, the cold plan differs from a
// fresh session's in the last digits (some algorithm state survives ColdStart; open).
TEST(Infeasibility, AfterAnInfeasibleStepAColdSolveIsAFreshSessions) {
  auto inst = bench::LoadBenchmarkInstance(nupmpc::testing::BenchmarkPath("masses_N30"));
  ASSERT_TRUE(inst.ok()) << inst.status();
  const auto& x1 = inst->closed_loop->x1;
  SolveLimits cold;
  cold.warm_start = false;
  auto fresh = Session::Create(inst->problem, Capped());
  ASSERT_TRUE(fresh.ok());
  ASSERT_THAT((*fresh)->SetInitialState(x1[7]), testing::IsOk());
  Solution fresh_plan;
  auto reference = (*fresh)->Solve(cold, &fresh_plan);
  ASSERT_TRUE(reference.ok());

  auto session = Session::Create(inst->problem, Capped());
  ASSERT_TRUE(session.ok());
  ASSERT_THAT((*session)->SetInitialState(x1[4]), testing::IsOk());
  ASSERT_TRUE((*session)->Solve(nullptr).ok());
  ASSERT_THAT((*session)->SetInitialState(Eigen::VectorXd::Constant(12, 3.9)), testing::IsOk());
  auto infeasible = (*session)->Solve(nullptr);
  ASSERT_TRUE(infeasible.ok());
  ASSERT_EQ(infeasible->status, SolveStatus::kInfeasible);
  ASSERT_THAT((*session)->SetInitialState(x1[7]), testing::IsOk());
  Solution plan;
  auto again = (*session)->Solve(cold, &plan);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->status, SolveStatus::kConverged);
  EXPECT_EQ(again->iterations, reference->iterations);
  EXPECT_NEAR(again->objective, reference->objective, 1e-12 * std::abs(reference->objective));
  EXPECT_LE((plan.inputs - fresh_plan.inputs).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(Infeasibility, TheElasticFallbackTakesOverAsSoonAsItIsFound) {
  SolverOptions options = Capped();
  options.elastic_slope = 1e3;
  auto session = Session::Create(Integrator(5.0), options);
  ASSERT_TRUE(session.ok());
  auto summary = (*session)->Solve(nullptr);
  ASSERT_TRUE(summary.ok());
  EXPECT_EQ(summary->status, SolveStatus::kInfeasible);
  EXPECT_TRUE(summary->elastic);
  EXPECT_NEAR(summary->max_violation, 3.9, 1e-9);  // the least-penalty plan (elastic_test)
  EXPECT_LT(summary->iterations, options.elastic_after_iterations) << summary->Describe();
}

// The detector on synthetic pass sequences (largest |ỹ|, violation, objective settled).
constexpr double kTolerance = 1e-9;
constexpr int kExplosivePasses = 1 + InfeasibilityWatch::kWindow * InfeasibilityWatch::kExplosiveWindows;
constexpr int kStalledPasses = 1 + InfeasibilityWatch::kWindow * InfeasibilityWatch::kStalledWindows;

int PassesUntilFound(InfeasibilityWatch* watch, int max_passes, double (*dual)(int), double (*violation)(int),
                     bool settled) {
  watch->Start();
  for (int k = 0; k < max_passes; ++k) {
    if (watch->Observe(dual(k), violation(k), settled, kTolerance)) return k + 1;
  }
  return 0;
}

TEST(InfeasibilityWatch, GeometricDualGrowthWithAPersistentViolationIsFound) {
  InfeasibilityWatch watch;
  EXPECT_EQ(PassesUntilFound(
                &watch, 1000, [](int k) { return std::pow(1.5, k); }, [](int) { return 0.1; }, false),
            kExplosivePasses);
}

TEST(InfeasibilityWatch, ACreepingDualUnderAStillIterateIsFound) {
  InfeasibilityWatch watch;
  EXPECT_EQ(PassesUntilFound(
                &watch, 1000, [](int k) { return 1.0 + 1e-4 * k; }, [](int) { return 1e-4; }, true),
            kStalledPasses);
  // While the iterate still moves, a creeping dual proves nothing.
  EXPECT_EQ(PassesUntilFound(
                &watch, 1000, [](int k) { return 1.0 + 1e-4 * k; }, [](int) { return 1e-4; }, false),
            0);
}

TEST(InfeasibilityWatch, ConvergingDualsOrAFallingViolationAreNeverFound) {
  InfeasibilityWatch watch;
  // Multipliers rising to a finite limit while the violation goes to zero.
  EXPECT_EQ(PassesUntilFound(
                &watch, 1000, [](int k) { return 1e3 * (1.0 - std::pow(0.5, k + 1)); },
                [](int k) { return std::pow(0.5, k); }, true),
            0);
  // Fast dual growth while the violation falls geometrically (a feasible cold start).
  EXPECT_EQ(PassesUntilFound(
                &watch, 40, [](int k) { return std::pow(2.0, k); }, [](int k) { return std::pow(0.8, k); }, false),
            0);
  // No multipliers (IAKE, IBFFD) or a violation within the tolerance.
  EXPECT_EQ(PassesUntilFound(
                &watch, 1000, [](int) { return 0.0; }, [](int) { return 1.0; }, true),
            0);
  EXPECT_EQ(PassesUntilFound(
                &watch, 1000, [](int k) { return std::pow(1.5, k); }, [](int) { return 1e-10; }, true),
            0);
}

}  // namespace
}  // namespace nupmpc::core
