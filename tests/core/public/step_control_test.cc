// The step-control rules the core's SequentialSolver and the client's NonlinearSession
// share: which plans are discarded, how the proximal scale moves, and which fields are
// refused. The decision the two copies had drifted on is pinned here: a solve cut short by
// the caller's budget for the whole sequence is not discarded for stopping, but it is for
// a model error its step does not warrant.
#include "core/public/standalone/step_control.h"

#include <limits>
#include <string>

#include "gtest/gtest.h"

namespace nupmpc {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

StepControl Controlled() {
  StepControl control;
  control.growth = 2.0;
  control.max_scale = 8.0;
  control.shrink = 4.0;
  control.model_error = 0.1;
  control.violation_floor = 1e-6;
  return control;
}

TEST(StepControl, OffKeepsEveryPlan) {
  const StepControl off;
  EXPECT_FALSE(off.active());
  EXPECT_FALSE(off.Rejects(StepTrial{true, 1.0, 0.1}, 0.0));
}

TEST(StepControl, ASolveAtItsOwnCapIsDiscardedWhateverItsModelError) {
  EXPECT_TRUE(Controlled().Rejects(StepTrial{true, 0.0, 1.0}, kInfinity));
}

// Stopping at the budget's end says nothing about the linearisation: such a plan is kept
// when the model predicted it well, and discarded like any other when it did not.
TEST(StepControl, ASolveCutShortByTheCallersBudgetIsJudgedByItsModelError) {
  const StepControl control = Controlled();
  const double step = 1.0, accepted_violation = 0.01;
  EXPECT_FALSE(control.Rejects(StepTrial{false, 0.05, step}, accepted_violation));
  EXPECT_TRUE(control.Rejects(StepTrial{false, 0.5, step}, accepted_violation));
}

TEST(StepControl, APlanThatHalvedTheAcceptedViolationIsKeptWhateverItsStep) {
  const StepControl control = Controlled();
  EXPECT_FALSE(control.Rejects(StepTrial{false, 0.4, 0.0}, 0.8));
  EXPECT_TRUE(control.Rejects(StepTrial{false, 0.41, 0.0}, 0.8));
  // Below the floor, a violation is never a reason.
  EXPECT_FALSE(control.Rejects(StepTrial{false, 1e-7, 0.0}, 1e-8));
}

TEST(StepControl, TheScaleGrowsToItsMaximumAndShrinksByTheFactor) {
  const StepControl control = Controlled();
  EXPECT_EQ(control.Grown(1.0), 2.0);
  EXPECT_EQ(control.Grown(6.0), 8.0);
  EXPECT_EQ(control.Grown(8.0), 8.0);
  EXPECT_EQ(control.Shrunk(8.0), 2.0);
  EXPECT_EQ(control.ToleranceFactor(8.0), 1.0);
  EXPECT_EQ(control.ToleranceFactor(2.0), 1.0 / 16.0);
}

TEST(StepControl, TheFirstFieldOutOfRangeIsNamed) {
  EXPECT_FALSE(Controlled().FirstInvalid().has_value());
  const auto field_of = [](StepControl control) {
    const auto bad = control.FirstInvalid();
    return bad.has_value() ? std::string(bad->field) : std::string("none");
  };
  StepControl c = Controlled();
  c.growth = 0.5;
  EXPECT_EQ(field_of(c), "growth");
  c = Controlled();
  c.max_scale = kInfinity;
  EXPECT_EQ(field_of(c), "max_scale");
  c = Controlled();
  c.shrink = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(field_of(c), "shrink");
  c = Controlled();
  c.model_error = 0.0;
  EXPECT_EQ(field_of(c), "model_error");
  c = Controlled();
  c.violation_floor = -1.0;
  EXPECT_EQ(field_of(c), "violation_floor");
}

}  // namespace
}  // namespace nupmpc
