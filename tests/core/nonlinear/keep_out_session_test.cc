// KeepOutSession: keep-out regions in a receding-horizon session. Cold solves keep out
// and reach the goal; warm solves after the plant moved keep out too and need fewer
// passes than cold ones on the same state; updates are validated first (a rejected one
// changes nothing); limits hold over all linearisations.
#include "core/nonlinear/keep_out_session.h"

#include <algorithm>
#include <atomic>

#include "core/examples/scenarios/obstacle_avoidance.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

using ::nupmpc::testing::StatusIs;
using ::testing::HasSubstr;

constexpr int kHorizon = 30;

KeepOut MixedScene() {
  KeepOut keep_out;
  keep_out.regions = examples::MixedShapesScene(kInfinity);
  return keep_out;
}

std::unique_ptr<KeepOutSession> MakeSession(const KeepOut& keep_out) {
  auto session = KeepOutSession::Create(examples::ObstaclePlant(kHorizon), keep_out);
  EXPECT_TRUE(session.ok()) << session.status();
  return session.ok() ? *std::move(session) : nullptr;
}

double MinClearance(const KeepOut& keep_out, const Solution& plan) {
  double clearance = kInfinity;
  for (int n = 1; n < plan.outputs.rows(); ++n) {
    for (const KeepOutRegion& region : keep_out.regions) {
      clearance = std::min(clearance, KeepOutClearance(region, plan.outputs.row(n).transpose()));
    }
  }
  return clearance;
}

TEST(KeepOutSession, ColdSolveKeepsOutAndReachesTheGoal) {
  const KeepOut keep_out = MixedScene();
  auto session = MakeSession(keep_out);
  ASSERT_NE(session, nullptr);
  Solution plan;
  auto summary = session->Solve(SolveLimits{}, &plan);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->status, SolveStatus::kConverged) << summary->Describe();
  EXPECT_GE(summary->linearisations, 2);
  EXPECT_EQ(plan.outputs.cols(), 2) << "the caller sees the plant's outputs only";
  EXPECT_GE(MinClearance(keep_out, plan), -1e-9);
  EXPECT_LE(summary->max_violation, 1e-6);
  EXPECT_NEAR(plan.states(kHorizon, 1), 3.0, 1e-6);
  EXPECT_NEAR(plan.states(kHorizon, 3), 3.0, 1e-6);
}

// The plant follows u[0] of each plan; every period is solved warm (shifted) and, for
// comparison, cold on a twin session with the same state.
TEST(KeepOutSession, WarmRecedingHorizonKeepsOutWithFewerPasses) {
  const KeepOut keep_out = MixedScene();
  auto warm = MakeSession(keep_out);
  auto cold = MakeSession(keep_out);
  ASSERT_NE(warm, nullptr);
  ASSERT_NE(cold, nullptr);
  const Problem plant = examples::ObstaclePlant(kHorizon);
  Solution plan, cold_plan;
  ASSERT_TRUE(warm->Solve(SolveLimits{}, &plan).ok());
  Eigen::VectorXd x = plant.initial_mean;
  int warm_passes = 0, cold_passes = 0;
  for (int period = 0; period < 10; ++period) {
    x = plant.A[0] * x + plant.B[0] * plan.inputs.row(0).transpose();
    ASSERT_TRUE(warm->SetInitialState(x).ok());
    ASSERT_TRUE(cold->SetInitialState(x).ok());
    warm->ShiftWarmStart();
    auto warm_summary = warm->Solve(SolveLimits{}, &plan);
    SolveLimits cold_limits;
    cold_limits.warm_start = false;
    auto cold_summary = cold->Solve(cold_limits, &cold_plan);
    ASSERT_TRUE(warm_summary.ok() && cold_summary.ok());
    EXPECT_TRUE(warm_summary->warm_started);
    EXPECT_EQ(warm_summary->status, SolveStatus::kConverged) << "period " << period << ": " << warm_summary->Describe();
    EXPECT_GE(MinClearance(keep_out, plan), -1e-9) << "period " << period;
    EXPECT_EQ(plan.states.row(0), x.transpose());
    warm_passes += warm_summary->iterations;
    cold_passes += cold_summary->iterations;
  }
  EXPECT_LT(warm_passes, cold_passes);
}

TEST(KeepOutSession, UpdateMovesTheGoalAndARejectedUpdateChangesNothing) {
  const KeepOut keep_out = MixedScene();
  auto session = MakeSession(keep_out);
  ASSERT_NE(session, nullptr);
  Solution before, after;
  ASSERT_TRUE(session->Solve(SolveLimits{}, &before).ok());

  Problem wrong = session->problem();
  wrong.terminal.reset();  // another shape
  EXPECT_THAT(session->Update(wrong), StatusIs(absl::StatusCode::kFailedPrecondition, HasSubstr("terminal")));
  Problem invalid = session->problem();
  invalid.mutable_input_prior(3, 1) = ScalarPrior::Gaussian(0.0, -1.0);
  EXPECT_EQ(session->Update(invalid).code(), absl::StatusCode::kInvalidArgument);
  SolveLimits keep;
  ASSERT_TRUE(session->Solve(keep, &after).ok());
  EXPECT_LE((after.inputs - before.inputs).cwiseAbs().maxCoeff(), 1e-6) << "rejected updates changed the problem";

  Problem moved = session->problem();
  moved.terminal->target << 0.0, 2.5, 0.0, 3.2;
  ASSERT_TRUE(session->Update(moved).ok());
  auto summary = session->Solve(keep, &after);
  ASSERT_TRUE(summary.ok());
  EXPECT_NEAR(after.states(kHorizon, 1), 2.5, 1e-6);
  EXPECT_NEAR(after.states(kHorizon, 3), 3.2, 1e-6);
  EXPECT_GE(MinClearance(keep_out, after), -1e-9);
}

TEST(KeepOutSession, IterationCapHoldsOverAllLinearisations) {
  auto session = MakeSession(MixedScene());
  ASSERT_NE(session, nullptr);
  SolveLimits limits;
  limits.max_iterations = 7;
  Solution plan;
  auto summary = session->Solve(limits, &plan);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_LE(summary->iterations, 7);
  EXPECT_NE(summary->status, SolveStatus::kConverged);
}

// has_plan: a cancelled solve (cold or warm) carries no plan and leaves the session
// usable; a solve after it plans again for the current state.
TEST(KeepOutSession, ACancelledSolveHasNoPlanAndTheNextOneDoes) {
  auto session = MakeSession(MixedScene());
  ASSERT_NE(session, nullptr);
  std::atomic<bool> cancel{true};
  SolveLimits cancelled;
  cancelled.cancel = &cancel;
  Solution plan;
  auto cold = session->Solve(cancelled, &plan);
  ASSERT_TRUE(cold.ok()) << cold.status();
  EXPECT_EQ(cold->status, SolveStatus::kCancelled) << cold->Describe();
  EXPECT_FALSE(cold->has_plan);
  EXPECT_EQ(plan.inputs.size(), 0);
  EXPECT_EQ(plan.states.size(), 0);

  auto solved = session->Solve(SolveLimits{}, &plan);
  ASSERT_TRUE(solved.ok()) << solved.status();
  EXPECT_EQ(solved->status, SolveStatus::kConverged) << solved->Describe();
  EXPECT_TRUE(solved->has_plan);
  ASSERT_EQ(plan.inputs.rows(), kHorizon);

  // Warm, after the plant moved: cancelled, then solved for the new state.
  const Eigen::VectorXd x1 = plan.states.row(1).transpose();
  session->ShiftWarmStart();
  ASSERT_TRUE(session->SetInitialState(x1).ok());
  auto warm = session->Solve(cancelled, &plan);
  ASSERT_TRUE(warm.ok()) << warm.status();
  EXPECT_FALSE(warm->has_plan) << warm->Describe();
  EXPECT_EQ(plan.inputs.size(), 0);
  auto again = session->Solve(SolveLimits{}, &plan);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->has_plan) << again->Describe();
  ASSERT_EQ(plan.states.rows(), kHorizon + 1);
  EXPECT_LE((plan.states.row(0).transpose() - x1).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(KeepOutSession, BadRegionsAreRefusedNamingTheField) {
  KeepOut keep_out = MixedScene();
  keep_out.regions[2].half_axes(1) = 0.0;
  EXPECT_THAT(KeepOutSession::Create(examples::ObstaclePlant(kHorizon), keep_out).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("keep_out.regions[2].half_axes")));
  keep_out = MixedScene();
  keep_out.second_output = 5;
  EXPECT_THAT(KeepOutSession::Create(examples::ObstaclePlant(kHorizon), keep_out).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("keep_out.second_output")));
}

}  // namespace
}  // namespace nupmpc::core
