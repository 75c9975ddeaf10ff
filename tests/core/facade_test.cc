// The embedding facade core/nupmpc.h: this translation unit includes nothing else of the
// core, so it compiles only if the facade is self-sufficient, and the checks below fail the
// build if the facade drags the algorithms' interface or the session internals in.
#include "core/nupmpc.h"

#ifdef NUPMPC_CORE_ALGORITHMS_OUTER_ITERATION_H_
#error "core/nupmpc.h exposes core/algorithms/outer_iteration.h"
#endif
#ifdef NUPMPC_CORE_SESSION_SESSION_H_
#error "core/nupmpc.h exposes core/session/session.h"
#endif

#include <cmath>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc::core {
namespace {

// A double integrator brought to rest from x[0] = (5, 0) with |u| <= 1.
Problem BoundedDoubleIntegrator() {
  Problem p = Problem::TimeInvariant(/*M=*/2, /*L=*/1, /*K=*/1, /*N=*/30);
  p.A[0] << 1.0, 1.0, 0.0, 1.0;
  p.B[0] << 0.5, 1.0;
  p.C[0] << 1.0, 0.0;
  p.initial_mean = (Eigen::VectorXd(2) << 5.0, 0.0)
                       .finished();  // not Vector2d: GCC 12 -Warray-bounds false positive on its AVX load
  for (ScalarPrior& prior : p.input_priors) {
    prior = ScalarPrior::Box(-1.0, 1.0);
    prior.mean = 0.0;
    prior.variance = 1.0;
  }
  for (ScalarPrior& prior : p.output_priors) prior = ScalarPrior::Gaussian(0.0, 0.1);
  return p;
}

TEST(Facade, CreatesASessionThatSolvesWithinTheInputBounds) {
  absl::StatusOr<std::unique_ptr<MpcSession>> session = CreateSession(BoundedDoubleIntegrator());
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_EQ((*session)->algorithm(), Algorithm::kIbffd);  // constraints on inputs only
  Solution plan;
  const absl::StatusOr<SolveSummary> summary = (*session)->Solve(SolveLimits{}, &plan);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->status, SolveStatus::kConverged) << summary->Describe();
  ASSERT_TRUE(summary->has_plan);
  ASSERT_EQ(plan.inputs.rows(), 30);
  EXPECT_LE(plan.inputs.cwiseAbs().maxCoeff(), 1.0 + 1e-9);
  EXPECT_LT(plan.inputs(0, 0), -0.99);  // braking hard from x = 5
}

TEST(Facade, RejectsAnInvalidProblemNamingTheField) {
  Problem p = BoundedDoubleIntegrator();
  p.A[0].resize(2, 3);
  const absl::StatusOr<std::unique_ptr<MpcSession>> session = CreateSession(std::move(p));
  ASSERT_FALSE(session.ok());
  EXPECT_THAT(std::string(session.status().message()), ::testing::HasSubstr("Problem.A"));
}

// Input differences through the facade: |u[n] - u[n-1]| <= 0.2 from u[-1] = 0.5, with the
// caller's one input in the plan, and a step that moves x[0] and gives u[-1].
TEST(Facade, CreatesAnInputDifferenceSessionThatKeepsItsRateLimit) {
  const Problem base = BoundedDoubleIntegrator();
  InputMap map;
  map.differences = true;
  map.difference_priors.assign(static_cast<std::size_t>(base.horizon), ScalarPrior::Box(-0.2, 0.2));
  map.previous_input = Eigen::VectorXd::Constant(1, 0.5);
  absl::StatusOr<std::unique_ptr<MpcSession>> session = CreateSession(base, map);
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_EQ((*session)->dimensions().num_inputs, 1);
  for (const double previous : {0.5, -0.3}) {
    StepUpdate step;
    step.state = Eigen::VectorXd::Constant(2, 1.0);
    step.previous_input = Eigen::VectorXd::Constant(1, previous);
    ASSERT_TRUE((*session)->Apply(step).ok());
    Solution plan;
    const absl::StatusOr<SolveSummary> summary = (*session)->Solve(SolveLimits{}, &plan);
    ASSERT_TRUE(summary.ok() && summary->has_plan) << summary.status();
    ASSERT_EQ(plan.inputs.cols(), 1);
    ASSERT_EQ(plan.states.cols(), 2);
    EXPECT_LE(std::abs(plan.inputs(0, 0) - previous), 0.2 + 1e-9);
    for (int n = 1; n < plan.inputs.rows(); ++n) {
      EXPECT_LE(std::abs(plan.inputs(n, 0) - plan.inputs(n - 1, 0)), 0.2 + 1e-9) << "step " << n;
    }
    EXPECT_EQ(plan.states(0, 0), 1.0);
  }
}

}  // namespace
}  // namespace nupmpc::core
