// GP session snapshots: the oracle of snapshot_oracle.h on the tanh plant of [Nghiem]
// (core/examples/scenarios/gp_tanh.h), with a reference change before a snapshot.

#include <memory>

#include "core/examples/scenarios/gp_tanh.h"
#include "core/gp/gp_model.h"
#include "core/gp/gp_mpc_session.h"
#include "gtest/gtest.h"
#include "tests/core/snapshot/snapshot_oracle.h"

namespace nupmpc::gp {
namespace {

using ::nupmpc::testing::ExpectRestoredTwinsMatch;
using ::nupmpc::testing::OracleRun;
using ::nupmpc::testing::SessionFactory;

std::shared_ptr<const GpModel> TanhModel() {
  absl::StatusOr<NarxData> data = examples::TanhTrainingData(100, 2);
  EXPECT_TRUE(data.ok()) << data.status();
  SeArdKernel kernel;  // near the fitted one of lingp_scp_test (no fit: the test is about snapshots)
  kernel.length_scales = Eigen::Vector2d(1.0, 1.0);
  kernel.noise_variance = examples::kTanhNoiseStd * examples::kTanhNoiseStd;
  absl::StatusOr<GpModel> model = GpModel::Create(data->regressors, data->targets, kernel);
  EXPECT_TRUE(model.ok()) << model.status();
  return std::make_shared<const GpModel>(*std::move(model));
}

TEST(GpSnapshot, RestoredTwinsGiveBitIdenticalPlans) {
  const std::shared_ptr<const GpModel> model = TanhModel();
  const SessionFactory make = [model]() -> std::unique_ptr<core::MpcSession> {
    absl::StatusOr<std::unique_ptr<GpMpcSession>> s =
        GpMpcSession::Create(model, examples::TanhMpcProblem(), {}, Eigen::VectorXd::Constant(1, -0.5));
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? *std::move(s) : nullptr;
  };
  OracleRun run;
  run.steps = 9;
  run.snapshot_before = {0, 1, 3, 5};
  run.first_state = Eigen::VectorXd::Zero(make()->problem().num_states);
  run.extra = [](int step, const core::MpcSession&, core::StepUpdate* update) {
    if (step == 2) update->reference = Eigen::VectorXd::Constant(1, -0.2);
  };
  run.disturbance = 0.05;  // the plant is not the GP
  EXPECT_EQ(ExpectRestoredTwinsMatch(make, run, "gp tanh"), 12);
}

}  // namespace
}  // namespace nupmpc::gp
