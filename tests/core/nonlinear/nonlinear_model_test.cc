// Sequential linearisation of a user's nonlinear model: the plan converges to the
// nonlinear optimum (checked against a one-dimensional Newton solve of the same
// problem), its model defect vanishes, trust regions bound each step, and the race-track
// model's hand-written Jacobians agree with finite differences.
#include "core/nonlinear/nonlinear_model.h"

#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "core/examples/scenarios/race_track.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

using ::nupmpc::testing::StatusIs;
using ::testing::HasSubstr;

constexpr double kInputVariance = 0.5, kTargetVariance = 0.01, kTarget = 1.2;

// x[n+1] = x + 0.5 sin(u), y = x³.
NonlinearModel SineCubeModel() {
  NonlinearModel m;
  m.num_states = m.num_inputs = m.num_outputs = 1;
  m.transition = [](int, const Eigen::VectorXd& x, const Eigen::VectorXd& u, Eigen::VectorXd* next, Eigen::MatrixXd* A,
                    Eigen::MatrixXd* B) {
    (*next)(0) = x(0) + 0.5 * std::sin(u(0));
    (*A)(0, 0) = 1.0;
    (*B)(0, 0) = 0.5 * std::cos(u(0));
  };
  m.output = [](int, const Eigen::VectorXd& x, Eigen::VectorXd* y, Eigen::MatrixXd* C) {
    (*y)(0) = x(0) * x(0) * x(0);
    (*C)(0, 0) = 3 * x(0) * x(0);
  };
  return m;
}

// One step: minimise ½u²/σu + ½(y[1] - target)²/σy with y[1] = (x0 + 0.5 sin u)³.
Problem OneStepProblem(double x0) {
  Problem p = Problem::TimeInvariant(1, 1, 1, 1);
  p.initial_mean = Eigen::VectorXd::Constant(1, x0);
  p.input_priors[0] = ScalarPrior::Gaussian(0.0, kInputVariance);
  p.mutable_output_prior(1, 0) = ScalarPrior::Gaussian(kTarget, kTargetVariance);
  return p;
}

// The same optimum by Newton's method on the scalar objective (numerical derivatives of
// the closed-form cost), from a grid's best point.
double OneStepOptimum(double x0) {
  const auto cost = [&](double u) {
    const double y = std::pow(x0 + 0.5 * std::sin(u), 3);
    return 0.5 * u * u / kInputVariance + 0.5 * (y - kTarget) * (y - kTarget) / kTargetVariance;
  };
  double best = -3.0;
  for (double u = -3.0; u <= 3.0; u += 1e-3) best = cost(u) < cost(best) ? u : best;
  for (int i = 0; i < 50; ++i) {
    const double h = 1e-5;
    const double g = (cost(best + h) - cost(best - h)) / (2 * h);
    const double H = (cost(best + h) - 2 * cost(best) + cost(best - h)) / (h * h);
    best -= g / H;
  }
  return best;
}

Solution ZeroGuess(const Problem& p) {
  Solution s;
  s.inputs = Eigen::MatrixXd::Zero(p.horizon, p.num_inputs);
  s.states = p.initial_mean.transpose().replicate(p.horizon + 1, 1);
  return s;
}

TEST(NonlinearModel, ConvergesToTheNonlinearOptimum) {
  for (const double x0 : {0.6, 0.8, 1.0}) {
    const Problem p = OneStepProblem(x0);
    auto linearisation = MakeModelLinearisation(SineCubeModel(), p);
    ASSERT_TRUE(linearisation.ok()) << linearisation.status();
    SequentialOptions options;
    options.step_tolerance = 1e-10;
    auto solver = SequentialSolver::Create(std::move(*linearisation), {}, options);
    ASSERT_TRUE(solver.ok()) << solver.status();
    Solution plan;
    auto summary = (*solver)->Solve(ZeroGuess(p), &plan);
    ASSERT_TRUE(summary.ok()) << summary.status();
    EXPECT_TRUE(summary->converged) << "x0 = " << x0;
    EXPECT_NEAR(plan.inputs(0, 0), OneStepOptimum(x0), 1e-6) << "x0 = " << x0;
    EXPECT_LT(summary->nonlinear_violation, 1e-9);
  }
}

TEST(NonlinearModel, ATrustRegionBoundsEachLinearisationsStep) {
  const Problem p = OneStepProblem(0.6);
  TrustRegion trust;
  trust.state_radius = Eigen::VectorXd::Constant(1, 0.05);
  auto linearisation = MakeModelLinearisation(SineCubeModel(), p, trust);
  ASSERT_TRUE(linearisation.ok()) << linearisation.status();
  SequentialOptions one;
  one.max_linearisations = 1;
  auto solver = SequentialSolver::Create(std::move(*linearisation), {}, one);
  ASSERT_TRUE(solver.ok()) << solver.status();
  Solution plan;
  ASSERT_TRUE((*solver)->Solve(ZeroGuess(p), &plan).ok());
  EXPECT_LE(std::abs(plan.states(1, 0) - 0.6), 0.05 + 1e-9);  // without it, x[1] moves ~0.4
  EXPECT_GT(std::abs(plan.states(1, 0) - 0.6), 0.05 - 1e-6);  // and the bound is active
  // Enough linearisations reach the same optimum as without a trust region.
  auto again = MakeModelLinearisation(SineCubeModel(), p, trust);
  auto full = SequentialSolver::Create(std::move(*again));
  ASSERT_TRUE(full.ok());
  auto summary = (*full)->Solve(ZeroGuess(p), &plan);
  ASSERT_TRUE(summary.ok());
  EXPECT_TRUE(summary->converged);
  EXPECT_NEAR(plan.inputs(0, 0), OneStepOptimum(0.6), 1e-6);
}

// Proximal terms of standard deviation σ on the state and the input.
TrustRegion Proximal(double stddev) {
  TrustRegion damping;
  damping.state_proximal_stddev = Eigen::VectorXd::Constant(1, stddev);
  damping.input_proximal_stddev = Eigen::VectorXd::Constant(1, stddev);
  return damping;
}

// Enough linearisations for a tight step tolerance.
SequentialOptions ToConvergence() {
  SequentialOptions options;
  options.step_tolerance = 1e-12;
  options.max_linearisations = 2000;
  return options;
}

// Proximal terms on the state and the input shorten every step but vanish at a fixed
// point: the plan still reaches the undamped optimum. A strong term (σ = 0.02 against a
// first step of ~0.4 in x[1]) keeps the first step short.
TEST(NonlinearModel, ProximalTermsShortenStepsButKeepTheOptimum) {
  const Problem p = OneStepProblem(0.6);
  const TrustRegion damping = Proximal(0.02);
  SequentialOptions one;
  one.max_linearisations = 1;
  auto first = SequentialSolver::Create(*MakeModelLinearisation(SineCubeModel(), p, damping), {}, one);
  ASSERT_TRUE(first.ok()) << first.status();
  Solution plan;
  ASSERT_TRUE((*first)->Solve(ZeroGuess(p), &plan).ok());
  EXPECT_LT(std::abs(plan.states(1, 0) - 0.6), 0.05);
  auto full = SequentialSolver::Create(*MakeModelLinearisation(SineCubeModel(), p, damping), {}, ToConvergence());
  ASSERT_TRUE(full.ok());
  auto summary = (*full)->Solve(ZeroGuess(p), &plan);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_TRUE(summary->converged);
  EXPECT_GT(summary->linearisations, 10);  // the damping did act
  EXPECT_NEAR(plan.inputs(0, 0), OneStepOptimum(0.6), 1e-6);
}

// The step control widens the proximal terms while the linear models predict well, so
// the same optimum needs far fewer linearisations than with the terms held fixed, and the
// terms end at their full width.
TEST(NonlinearModel, StepControlWidensTheProximalTermsWhileStepsSucceed) {
  const Problem p = OneStepProblem(0.6);
  const TrustRegion damping = Proximal(0.02);
  const SequentialOptions fixed = ToConvergence();
  SequentialOptions controlled = fixed;
  controlled.proximal_growth = 2.0;
  controlled.proximal_max_scale = 1e4;
  controlled.proximal_shrink = 4.0;
  int linearisations[2];
  for (int k = 0; k < 2; ++k) {
    auto solver =
        SequentialSolver::Create(*MakeModelLinearisation(SineCubeModel(), p, damping), {}, k == 0 ? fixed : controlled);
    ASSERT_TRUE(solver.ok());
    Solution plan;
    auto summary = (*solver)->Solve(ZeroGuess(p), &plan);
    ASSERT_TRUE(summary.ok()) << summary.status();
    EXPECT_TRUE(summary->converged);
    EXPECT_NEAR(plan.inputs(0, 0), OneStepOptimum(0.6), 1e-6);
    linearisations[k] = summary->linearisations;
    if (k == 1) {
      EXPECT_EQ(summary->proximal_scale, 1e4);
    }
  }
  EXPECT_LT(2 * linearisations[1], linearisations[0]);
}

// From a guess on the far side of sin's peak (u = 2.5, where the linearisation points
// the wrong way for a long step), wide proximal terms let the first linear models
// promise steps they cannot keep: the step control discards those plans, shrinks the
// terms and still converges to the optimum.
TEST(NonlinearModel, StepControlDiscardsStepsTheLinearModelMispredicts) {
  const Problem p = OneStepProblem(0.6);
  const TrustRegion damping = Proximal(10.0);
  SequentialOptions controlled = ToConvergence();
  controlled.proximal_growth = 2.0;
  controlled.proximal_max_scale = 4.0;
  controlled.proximal_shrink = 4.0;
  auto solver = SequentialSolver::Create(*MakeModelLinearisation(SineCubeModel(), p, damping), {}, controlled);
  ASSERT_TRUE(solver.ok());
  Solution guess = ZeroGuess(p), plan;
  guess.inputs(0, 0) = 2.5;
  guess.states(1, 0) = 0.6 + 0.5 * std::sin(2.5);
  auto summary = (*solver)->Solve(guess, &plan);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_GT(summary->rejected, 0);
  EXPECT_TRUE(summary->converged);
  EXPECT_NEAR(plan.inputs(0, 0), OneStepOptimum(0.6), 1e-6);
  EXPECT_LT(summary->nonlinear_violation, 1e-9);
}

TEST(NonlinearModel, BadShapesAreRefusedNamingTheField) {
  Problem p = OneStepProblem(0.6);
  p.num_outputs = 2;
  EXPECT_THAT(MakeModelLinearisation(SineCubeModel(), p).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("Problem.num_outputs")));
  TrustRegion trust;
  trust.state_radius = Eigen::VectorXd::Constant(2, 1.0);
  EXPECT_THAT(MakeModelLinearisation(SineCubeModel(), OneStepProblem(0.6), trust).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("TrustRegion.state_radius")));
  trust.state_radius = Eigen::VectorXd::Constant(1, -1.0);
  EXPECT_THAT(MakeModelLinearisation(SineCubeModel(), OneStepProblem(0.6), trust).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("state_radius[0]")));
  trust = TrustRegion{};
  trust.state_proximal_stddev = Eigen::VectorXd::Constant(1, 0.0);
  EXPECT_THAT(MakeModelLinearisation(SineCubeModel(), OneStepProblem(0.6), trust).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("TrustRegion.state_proximal_stddev[0]")));
  trust = TrustRegion{};
  trust.input_proximal_stddev = Eigen::VectorXd::Constant(3, 1.0);
  EXPECT_THAT(MakeModelLinearisation(SineCubeModel(), OneStepProblem(0.6), trust).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("TrustRegion.input_proximal_stddev")));
  for (const auto& [field, set] : std::vector<std::pair<std::string, std::function<void(SequentialOptions&)>>>{
           {"proximal_growth", [](SequentialOptions& o) { o.proximal_growth = 0.5; }},
           {"proximal_max_scale", [](SequentialOptions& o) { o.proximal_max_scale = std::nan(""); }},
           {"proximal_shrink", [](SequentialOptions& o) { o.proximal_shrink = 0.0; }},
           {"proximal_model_error", [](SequentialOptions& o) { o.proximal_model_error = -1.0; }},
           {"proximal_violation_floor", [](SequentialOptions& o) { o.proximal_violation_floor = -1.0; }}}) {
    SequentialOptions bad;
    set(bad);
    EXPECT_THAT(Validate(bad), StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(field)));
  }
  NonlinearModel no_output = SineCubeModel();
  no_output.output = nullptr;
  EXPECT_THAT(MakeModelLinearisation(no_output, OneStepProblem(0.6)).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("NonlinearModel")));
  auto solver = SequentialSolver::Create(*MakeModelLinearisation(SineCubeModel(), OneStepProblem(0.6)));
  ASSERT_TRUE(solver.ok());
  Solution wrong;
  wrong.inputs = Eigen::MatrixXd::Zero(2, 1);
  wrong.states = Eigen::MatrixXd::Zero(2, 1);
  EXPECT_THAT((*solver)->Solve(wrong, nullptr).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("initial_guess.inputs")));
}

TEST(RaceTrackModel, JacobiansMatchFiniteDifferences) {
  const examples::Track track = examples::DemoTrack();
  const NonlinearModel model = examples::RaceModel(track, {}, 1000);
  Eigen::VectorXd x(6), u(2);
  x << 0.002, 0.15, 0.4, -0.3, 0.2, 1.0;
  u << 0.5, -0.7;
  for (const int n : {0, 40, 130, 500}) EXPECT_LT(JacobianError(model, n, x, u), 1e-7) << "step " << n;
}

TEST(RaceTrack, TheDemoTrackIsClosed) {
  const examples::Track track = examples::DemoTrack();
  EXPECT_LT(track.point(track.length() - 1e-12).norm(), 1e-9);
}

}  // namespace
}  // namespace nupmpc::core
