// Keep-out regions through the v1 API: SolveOnce gives the core KeepOutSession's plan in
// the plant's outputs; a session driven in receding horizon keeps out at every period and
// re-converges warm in fewer passes than its cold first solve; Δu priors combine with
// regions; bad regions are refused naming the field.
#include <algorithm>
#include <numbers>

#include "core/examples/scenarios/obstacle_avoidance.h"
#include "core/nonlinear/keep_out_session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;
constexpr int kN = 30;

v1::KeepOutRegion RegionProto(const core::KeepOutRegion& region) {
  v1::KeepOutRegion r;
  r.set_shape(region.shape == core::KeepOutShape::kRectangle ? v1::KeepOutRegion::SHAPE_RECTANGLE
                                                             : v1::KeepOutRegion::SHAPE_ELLIPSE);
  r.set_centre_x(region.centre(0));
  r.set_centre_y(region.centre(1));
  r.set_half_axis_a(region.half_axes(0));
  r.set_half_axis_b(region.half_axes(1));
  r.set_rotation_rad(region.rotation);
  return r;
}

v1::ProblemSpec ObstacleSpec() {
  v1::ProblemSpec spec = SpecOrDie(examples::ObstaclePlant(kN));
  v1::KeepOut* keep_out = spec.mutable_keep_out();
  keep_out->set_first_output(0);
  keep_out->set_second_output(1);
  for (const core::KeepOutRegion& region : examples::MixedShapesScene(core::kInfinity)) {
    *keep_out->add_regions() = RegionProto(region);
  }
  return spec;
}

// Smallest clearance of the plan's points (steps 1..N) to the scene's regions.
double MinClearance(const v1::SolveResult& result) {
  double clearance = core::kInfinity;
  for (int n = 1; n <= kN; ++n) {
    const Eigen::Vector2d y(result.outputs(2 * n), result.outputs(2 * n + 1));
    for (const core::KeepOutRegion& region : examples::MixedShapesScene(core::kInfinity)) {
      clearance = std::min(clearance, core::KeepOutClearance(region, y));
    }
  }
  return clearance;
}

TEST_F(ServiceTest, KeepOutSolveOnceIsTheCoreSessionsPlan) {
  absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(ObstacleSpec());
  ASSERT_TRUE(once.ok()) << once.status();
  EXPECT_EQ(once->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_GE(once->linearisations(), 2u);
  EXPECT_LE(once->keep_out_violation(), 1e-9);
  ASSERT_EQ(once->outputs_size(), 2 * (kN + 1)) << "the plant's outputs only";
  EXPECT_GE(MinClearance(*once), -1e-9);

  core::KeepOut keep_out;
  keep_out.regions = examples::MixedShapesScene(core::kInfinity);
  auto session = core::KeepOutSession::Create(examples::ObstaclePlant(kN), keep_out);
  ASSERT_TRUE(session.ok()) << session.status();
  core::Solution plan;
  auto summary = (*session)->Solve(core::SolveLimits{}, &plan);
  ASSERT_TRUE(summary.ok());
  EXPECT_EQ(once->iterations(), static_cast<unsigned>(summary->iterations));
  for (int n = 0; n < kN; ++n) {
    EXPECT_NEAR(once->inputs(2 * n), plan.inputs(n, 0), 1e-12);
    EXPECT_NEAR(once->inputs(2 * n + 1), plan.inputs(n, 1), 1e-12);
  }
}

TEST_F(ServiceTest, KeepOutSessionKeepsOutEveryPeriodAndReconvergesWarm) {
  const core::Problem plant = examples::ObstaclePlant(kN);
  absl::StatusOr<std::unique_ptr<Session>> session = client_->OpenSession(ObstacleSpec());
  ASSERT_TRUE(session.ok()) << session.status();
  Eigen::VectorXd x = plant.initial_mean;
  unsigned first_passes = 0, warm_passes = 0;
  constexpr int kPeriods = 8;
  for (int period = 0; period <= kPeriods; ++period) {
    v1::Step step;
    for (int i = 0; i < 4; ++i) step.add_state(x(i));
    absl::StatusOr<v1::SolveResult> result = (*session)->Step(step);
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED) << "period " << period;
    EXPECT_GE(MinClearance(*result), -1e-9) << "period " << period;
    EXPECT_LE(result->max_violation(), 1e-6);
    EXPECT_EQ(result->warm_started(), period > 0);
    (period == 0 ? first_passes : warm_passes) += result->iterations();
    x = plant.A[0] * x + plant.B[0] * Eigen::Vector2d(result->inputs(0), result->inputs(1));
  }
  EXPECT_LT(warm_passes, first_passes * kPeriods) << "warm periods should average fewer passes than the cold one";
}

// Binding on this scene (the plan without it changes input by up to 0.03 per step). The
// Δu priors carry a small Gaussian part: input boxes together with output constraints
// then run on IFFBDD (50 passes); without it IAKE takes thousands per linearisation.
constexpr double kRate = 0.02;

TEST_F(ServiceTest, KeepOutCombinesWithRateLimits) {
  v1::ProblemSpec spec = ObstacleSpec();
  v1::InputDifferences* d = spec.mutable_input_differences();
  for (int l = 0; l < 2; ++l) {
    v1::ComponentPrior* c = d->add_priors();
    c->set_kind(v1::PRIOR_KIND_BOX);
    c->add_lower(-kRate);
    c->add_upper(kRate);
    c->add_weight(0.01);
  }
  absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
  ASSERT_TRUE(once.ok()) << once.status();
  EXPECT_EQ(once->status(), v1::SOLVE_STATUS_CONVERGED) << once->iterations() << " passes, " << once->linearisations()
                                                        << " linearisations, " << once->solve_ms() << " ms";
  EXPECT_GE(MinClearance(*once), -1e-9);
  for (int l = 0; l < 2; ++l) {
    double previous = 0.0;  // previous_input defaults to zeros
    for (int n = 0; n < kN; ++n) {
      EXPECT_LE(std::abs(once->inputs(2 * n + l) - previous), kRate + 1e-7) << "step " << n << " input " << l;
      previous = once->inputs(2 * n + l);
    }
  }
}

TEST_F(ServiceTest, BadKeepOutRegionsAreRefusedNamingTheField) {
  const auto refused = [&](v1::ProblemSpec spec, const std::string& field) {
    absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
    EXPECT_EQ(once.status().code(), absl::StatusCode::kInvalidArgument) << field;
    EXPECT_THAT(std::string(once.status().message()), HasSubstr(field));
  };
  v1::ProblemSpec spec = ObstacleSpec();
  spec.mutable_keep_out()->mutable_regions(1)->set_half_axis_a(-1.0);
  refused(spec, "spec.keep_out.regions[1].half_axis_a");
  spec = ObstacleSpec();
  spec.mutable_keep_out()->mutable_regions(2)->set_centre_y(std::numeric_limits<double>::quiet_NaN());
  refused(spec, "spec.keep_out.regions[2].centre_y");
  spec = ObstacleSpec();
  spec.mutable_keep_out()->set_second_output(2);
  refused(spec, "spec.keep_out.second_output");
  spec = ObstacleSpec();
  spec.mutable_keep_out()->set_second_output(0);
  refused(spec, "spec.keep_out.second_output");
  spec = ObstacleSpec();
  spec.mutable_keep_out()->clear_regions();
  refused(spec, "spec.keep_out.regions");
  spec = ObstacleSpec();
  spec.mutable_keep_out()->set_rectangle_order(1);
  refused(spec, "spec.keep_out.rectangle_order");
  spec = ObstacleSpec();
  spec.mutable_keep_out()->mutable_regions(0)->set_slope(-2.0);
  refused(spec, "spec.keep_out.regions[0].slope");
}

}  // namespace
}  // namespace nupmpc::testing
