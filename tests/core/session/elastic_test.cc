// The elastic fallback (SolverOptions.elastic_slope, core/session/elastic.h): an
// infeasible problem ends promptly with status infeasible and the least-penalty plan
// (checked against its closed form), a feasible one handed to the fallback early still
// reaches its reference optimum (the exact-penalty property), input bounds stay hard, and
// the session comes out of it unchanged.
#include <cmath>
#include <memory>

#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"
#include "tests/util/bounded_integrator.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

using ::testing::HasSubstr;
using testing::StatusIs;

constexpr int kHorizon = 20;
constexpr double kInputLimit = 0.1, kSlope = 1e3;

// From x0 = 5 the bound cannot be met within 20 steps (40 are needed).
Problem Integrator(double x0) { return testing::BoundedIntegrator(x0, kHorizon, kInputLimit); }

SolverOptions Elastic() {
  SolverOptions options;
  options.elastic_slope = kSlope;
  return options;
}

TEST(Elastic, AnInfeasibleProblemEndsPromptlyWithTheLeastPenaltyPlan) {
  auto session = Session::Create(Integrator(5.0), Elastic());
  ASSERT_TRUE(session.ok()) << session.status();
  Solution plan;
  auto summary = (*session)->Solve(&plan);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->status, SolveStatus::kInfeasible) << summary->Describe();
  EXPECT_TRUE(summary->elastic);
  EXPECT_LE(summary->iterations, Elastic().elastic_after_iterations + 100);
  // Closed form: the state is above the bound at every step, so each
  // input's marginal value is slope·(steps after it) ≫ its Gaussian cost: u ≡ -0.1 (its
  // hard limit), and the largest excess is x[1] - 1 = 3.9.
  for (int n = 0; n < kHorizon; ++n) EXPECT_NEAR(plan.inputs(n, 0), -kInputLimit, 1e-9) << n;
  EXPECT_NEAR(summary->max_violation, 3.9, 1e-9);
  for (int n = 1; n <= kHorizon; ++n) EXPECT_NEAR(plan.outputs(n, 0), 5.0 - kInputLimit * n, 1e-9) << n;
}

TEST(Elastic, WithoutItTheSameProblemIsFoundInfeasibleByItsMultipliers) {
  SolverOptions options;
  options.max_iterations = 1000;
  auto session = Session::Create(Integrator(5.0), options);
  ASSERT_TRUE(session.ok());
  auto summary = (*session)->Solve(nullptr);
  ASSERT_TRUE(summary.ok());
  // core/session/infeasibility.h: the hard problem's duals diverge; no penalty plan.
  EXPECT_EQ(summary->status, SolveStatus::kInfeasible);
  EXPECT_LT(summary->iterations, 1000);
  EXPECT_FALSE(summary->elastic);
}

// The exact-penalty property: a feasible problem handed to the fallback after one pass
// reaches reference.json's optimum, because the elastic minimiser meets every bound.
TEST(Elastic, AFeasibleProblemHandedOverEarlyStillReachesItsOptimum) {
  const std::string dir = NUPMPC_BENCHMARK_DIR;
  auto inst = bench::LoadBenchmarkInstance(dir + "/masses_N30.json");
  ASSERT_TRUE(inst.ok()) << inst.status();
  auto refs = bench::LoadReferences(dir + "/reference.json");
  ASSERT_TRUE(refs.ok()) << refs.status();
  SolverOptions options = Elastic();
  options.elastic_slope = 1e4;
  options.elastic_after_iterations = 1;
  options.polish_after_stable_iterations = 0;  // no early polish: the hard loop stops unconverged
  auto session = Session::Create(inst->problem, options);
  ASSERT_TRUE(session.ok()) << session.status();
  ASSERT_EQ((*session)->algorithm(), Algorithm::kIffbdd);
  auto summary = (*session)->Solve(nullptr);
  ASSERT_TRUE(summary.ok());
  EXPECT_TRUE(summary->elastic);
  EXPECT_EQ(summary->status, SolveStatus::kConverged) << summary->Describe();
  const double J_star = refs->at("masses_N30").J_star;
  EXPECT_LE(std::abs(summary->objective - J_star), 1e-8 * std::abs(J_star));
}

TEST(Elastic, TheSessionComesOutOfItUnchanged) {
  auto session = Session::Create(Integrator(5.0), Elastic());
  ASSERT_TRUE(session.ok());
  ASSERT_TRUE((*session)->Solve(nullptr).ok());
  // The hard bounds are back: a feasible state is solved as the hard problem, like a fresh
  // session does it.
  for (int n = 1; n <= kHorizon; ++n) EXPECT_TRUE((*session)->problem().output_prior(n, 0).is_hard());
  ASSERT_THAT((*session)->SetInitialState(Eigen::VectorXd::Constant(1, 0.7)), testing::IsOk());
  Solution plan, fresh_plan;
  auto again = (*session)->Solve(&plan);
  auto fresh = Session::Create(Integrator(0.7), Elastic());
  ASSERT_TRUE(again.ok() && fresh.ok());
  auto reference = (*fresh)->Solve(&fresh_plan);
  ASSERT_TRUE(reference.ok());
  EXPECT_EQ(again->status, SolveStatus::kConverged);
  EXPECT_FALSE(again->elastic);
  EXPECT_NEAR(again->objective, reference->objective, 1e-12 * (1 + std::abs(reference->objective)));
  EXPECT_LE((plan.inputs - fresh_plan.inputs).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(Elastic, OptionsAreValidated) {
  SolverOptions options;
  options.elastic_slope = -1.0;
  EXPECT_THAT(Validate(options), StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("elastic_slope = -1")));
  options.elastic_slope = std::nan("");
  EXPECT_THAT(Validate(options), StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("elastic_slope")));
  options = {};
  options.elastic_after_iterations = 0;
  EXPECT_THAT(Validate(options),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("elastic_after_iterations = 0")));
}

}  // namespace
}  // namespace nupmpc::core
