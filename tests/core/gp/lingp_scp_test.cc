// linGP-SCP on the example of [Nghiem] §V with N = 200 training points: every step of the
// closed loop converges, the plans satisfy the chance and terminal constraints under the
// exact GP, they equal Ipopt's plans on the same step problems (the full NLP with exact
// GP mean and variance, an independent solver), and the loop tracks the reference.
#include "core/gp/lingp_scp.h"

#include <atomic>
#include <cmath>

#include "core/examples/scenarios/gp_tanh.h"
#include "core/gp/hyperparameter_fit.h"
#include "gtest/gtest.h"
#include "loadtest/bench/gp/gp_closed_loop.h"

namespace nupmpc::gp {
namespace {

GpModel TanhModel(int points) {
  auto fit_data = examples::TanhTrainingData(200, 1);
  SeArdKernel start;
  start.signal_variance = 1.0;
  start.length_scales = Eigen::Vector2d(1.0, 1.0);
  start.noise_variance = 0.01;
  auto fit = FitHyperparameters(fit_data->regressors, fit_data->targets, start);
  EXPECT_TRUE(fit.ok() && fit->converged);
  // The fitted noise is the plant's measurement noise (std 0.025).
  EXPECT_NEAR(std::sqrt(fit->kernel.noise_variance), examples::kTanhNoiseStd, 0.01);
  auto data = examples::TanhTrainingData(points, 2);
  auto model = GpModel::Create(data->regressors, data->targets, fit->kernel);
  EXPECT_TRUE(model.ok()) << model.status();
  return *std::move(model);
}

TEST(LinGpScp, ClosedLoopMatchesIpoptAndSatisfiesTheConstraints) {
  const GpModel model = TanhModel(200);
  bench::GpClosedLoopOptions options;
  options.steps = 60;  // through the reference step at k = 51
  auto run = bench::RunGpClosedLoops(model, examples::TanhMpcProblem(), options);
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_EQ(run->scp.unconverged, 0);
  EXPECT_LE(run->scp.max_violation, 1e-9) << "chance/terminal constraints under the exact GP";
  EXPECT_EQ(run->ipopt.unconverged, 0);
  EXPECT_LE(run->max_plan_difference, 1e-3) << "linGP-SCP and Ipopt disagree on a step problem";
  EXPECT_LE(run->max_objective_gap, 1e-3);
  // Tracking: after settling, the output stays near the reference (noise std 0.025).
  for (int t = 10; t < 50; ++t) EXPECT_NEAR(run->scp.y(t), -0.5, 0.15) << "step " << t;
  for (int t = 56; t < 60; ++t) EXPECT_NEAR(run->scp.y(t), -0.2, 0.15) << "step " << t;
  EXPECT_NEAR(run->scp.tracking_rmse, run->ipopt.tracking_rmse, 0.01);
}

TEST(LinGpScp, WarmStepsNeedFewIterations) {
  const GpModel model = TanhModel(200);
  auto scp = LinGpScp::Create(&model, examples::TanhMpcProblem());
  ASSERT_TRUE(scp.ok());
  double y = 0.0, u = 0.0, x = 0.0;
  int warm_iterations = 0;
  for (int t = 0; t < 30; ++t) {
    (*scp)->ShiftWarmStart();
    ScpPlan plan;
    auto s = (*scp)->Solve(Eigen::VectorXd::Constant(1, y), Eigen::VectorXd::Constant(1, u),
                           Eigen::VectorXd::Constant(1, -0.5), &plan);
    ASSERT_TRUE(s.ok()) << s.status();
    ASSERT_TRUE(s->converged) << "step " << t;
    if (t >= 10) warm_iterations += s->iterations;
    u = plan.inputs(0);
    x = examples::TanhPlantStep(x, u);
    y = x;  // noise-free here
  }
  EXPECT_LE(warm_iterations, 20 * 4) << "settled warm steps should need a few SCP iterations";
}

// has_plan: only a plan the SCP accepted (or converged to) in this solve; a cancelled
// solve returns the nominal plan (the shifted previous one, or the cold guess) with
// has_plan false.
TEST(LinGpScp, HasAPlanOnlyAfterAnAcceptedStep) {
  const GpModel model = TanhModel(200);
  auto scp = LinGpScp::Create(&model, examples::TanhMpcProblem());
  ASSERT_TRUE(scp.ok());
  const Eigen::VectorXd y = Eigen::VectorXd::Constant(1, 0.0), u = Eigen::VectorXd::Constant(1, 0.0);
  const Eigen::VectorXd r = Eigen::VectorXd::Constant(1, -0.5);
  std::atomic<bool> cancel{true};
  core::SolveLimits cancelled;
  cancelled.cancel = &cancel;
  ScpPlan plan;
  auto c = (*scp)->Solve(y, u, r, &plan, &cancelled);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->status, core::SolveStatus::kCancelled);
  EXPECT_FALSE(c->has_plan);
  auto s = (*scp)->Solve(y, u, r, &plan);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_TRUE(s->converged);
  EXPECT_TRUE(s->has_plan);
  (*scp)->ShiftWarmStart();
  c = (*scp)->Solve(y, u, r, &plan, &cancelled);
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(c->has_plan) << "the shifted previous plan is not a plan for this state";
}

TEST(LinGpScp, BadArgumentsAreRefusedNamingTheField) {
  const GpModel model = TanhModel(50);
  GpMpcProblem p = examples::TanhMpcProblem();
  p.input_change_weight = 0.0;
  EXPECT_NE(LinGpScp::Create(&model, p).status().message().find("input_change_weight"), std::string::npos);
  p = examples::TanhMpcProblem();
  p.layout.input_lags = 2;  // the model has 2 regressors, this layout 4
  EXPECT_NE(LinGpScp::Create(&model, p).status().message().find("layout"), std::string::npos);
  auto scp = LinGpScp::Create(&model, examples::TanhMpcProblem());
  ASSERT_TRUE(scp.ok());
  ScpPlan plan;
  EXPECT_NE((*scp)
                ->Solve(Eigen::VectorXd::Zero(2), Eigen::VectorXd::Zero(1), Eigen::VectorXd::Zero(1), &plan)
                .status()
                .message()
                .find("past_outputs"),
            std::string::npos);
}

}  // namespace
}  // namespace nupmpc::gp
