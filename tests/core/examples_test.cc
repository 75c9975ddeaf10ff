// The [KL] applications' properties (core/examples/): what each example must show, at
// full size (each runs in well under a second). Obstacle avoidance is in keep_out_test.
#include <algorithm>
#include <cmath>

#include "core/examples/scenarios/corridor.h"
#include "core/examples/scenarios/dac.h"
#include "core/examples/scenarios/flappy_bird.h"
#include "gtest/gtest.h"

namespace nupmpc::examples {
namespace {

bool AllIn(const Eigen::VectorXd& v, std::initializer_list<double> levels) {
  for (const double x : v) {
    if (std::none_of(levels.begin(), levels.end(), [x](double level) { return x == level; })) return false;
  }
  return true;
}

TEST(DacExample, LongPlanIsExactlyBinaryAndTracksThePassbandTarget) {
  // nup-algorithms.md §7.2: EM with 2000 passes, rounded, MSE 2.8e-4 in the prototype.
  auto plan = DacLongPlan(450, 0.045, 2.0, 2000, /*em=*/true);
  ASSERT_TRUE(plan.ok()) << plan.status();
  EXPECT_TRUE(AllIn(plan->inputs, {0.0, 1.0}));
  EXPECT_LT(plan->mse, 2 * 2.8e-4);
  // Outside the passband the plant cannot follow: the error is about the target's own
  // variance (0.3²/2 = 0.045), far above the in-band error.
  auto outside = DacLongPlan(450, 0.045, 40.0, 300, true);
  ASSERT_TRUE(outside.ok()) << outside.status();
  EXPECT_GT(outside->mse, 50 * plan->mse);
}

class CorridorExample : public ::testing::TestWithParam<CorridorVersion> {};

TEST_P(CorridorExample, StaysInTheCorridorWithTheVersionsStructure) {
  auto run = RunCorridor(GetParam());
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_LE(run->max_corridor_violation, 1e-6);
  switch (GetParam()) {
    case CorridorVersion::kRateLimit: EXPECT_GE(run->min_input_change, -0.03 - 1e-9); break;
    case CorridorVersion::kSparseInput: EXPECT_LE(run->nonzero_inputs, 20); break;  // of 175
    case CorridorVersion::kSparseChanges: EXPECT_LE(run->input_switches, 20); break;
    default: break;
  }
}

INSTANTIATE_TEST_SUITE_P(ConvexAndSparse, CorridorExample,
                         ::testing::Values(CorridorVersion::kL2, CorridorVersion::kRateLimit,
                                           CorridorVersion::kSparseInput, CorridorVersion::kSparseChanges),
                         [](const auto& info) { return std::string(CorridorVersionName(info.param)); });

// Version 4 lands exactly on the three levels. It does not stay in the corridor yet
// (violation ≈ 5, see issue 4's note): that property is not claimed here.
TEST(CorridorExampleThreeLevels, InputsAreExactlyOnTheLevels) {
  auto run = RunCorridor(CorridorVersion::kThreeLevels);
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_TRUE(AllIn(run->inputs, {-1.0, 0.0, 1.0}));
  RecordProperty("corridor_violation", std::to_string(run->max_corridor_violation));
}

// Flappy bird: the flaps are exactly binary. The slits are not passed yet (see issue 4's
// note): not claimed here.
TEST(FlappyBirdExample, FlapsAreExactlyBinary) {
  auto run = FlyThroughWalls(300, RandomWalls(300, 5, 1), {});
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_TRUE(AllIn(run->flaps, {0.0, 1.0}));
  RecordProperty("slit_violation", std::to_string(run->worst_slit_violation));
}

}  // namespace
}  // namespace nupmpc::examples
