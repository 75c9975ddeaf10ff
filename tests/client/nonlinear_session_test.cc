// NonlinearSession (client/nonlinear_session.h) against a real server: the linearisation
// reaches the server as the model the user means (a linear plant gives the linear
// session's plan), finite-difference and analytic Jacobians agree and a wrong analytic one
// is refused naming its entry, SQP settles on a trajectory of the nonlinear model, and the
// bicycle example (client/examples/bicycle.h) keeps every bound in closed loop, tracks its
// path, reaches the goal, and warm-starts each period in a fraction of a cold solve's
// passes. Last, both example programs run against a spawned nupmpc-server.
#include "client/nonlinear_session.h"

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/channel_factory.h"
#include "client/examples/bicycle.h"
#include "client/examples/period_table.h"
#include "client/examples/race_track.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"
#include "tests/util/server_process.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::testing {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
namespace ex = api_examples;

double MaxAbsDifference(const std::vector<double>& a, const std::vector<double>& b) {
  EXPECT_EQ(a.size(), b.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  return worst;
}

// A linear plant with affine terms, written as a NonlinearModel: x⁺ = A x + B u + c,
// y = C x + d (a double integrator pushed by a constant force, measured with an offset).
constexpr double kA[4] = {1.0, 0.1, 0.0, 1.0}, kB[2] = {0.005, 0.1}, kC[2] = {1.0, 0.0};
constexpr double kStateOffset[2] = {0.01, -0.02}, kOutputOffset = 0.5;

NonlinearModel AffineModel() {
  NonlinearModel m;
  m.num_states = 2;
  m.num_inputs = 1;
  m.num_outputs = 1;
  m.transition = [](std::int64_t, const std::vector<double>& x, const std::vector<double>& u) {
    return std::vector<double>{kA[0] * x[0] + kA[1] * x[1] + kB[0] * u[0] + kStateOffset[0],
                               kA[2] * x[0] + kA[3] * x[1] + kB[1] * u[0] + kStateOffset[1]};
  };
  m.output = [](std::int64_t, const std::vector<double>& x) {
    return std::vector<double>{kC[0] * x[0] + kC[1] * x[1] + kOutputOffset};
  };
  return m;
}

// Priors and x[0] only: what NonlinearSession::Create takes.
v1::ProblemSpec AffineTemplate(int horizon) {
  v1::ProblemSpec spec;
  spec.mutable_model()->set_horizon(horizon);
  spec.mutable_initial_state()->add_mean(1.0);
  spec.mutable_initial_state()->add_mean(0.0);
  v1::ComponentPrior* u = spec.add_input_priors();
  u->set_kind(v1::PRIOR_KIND_BOX);  // active at the start: the plan is not the unconstrained one
  u->add_lower(-0.5);
  u->add_upper(0.5);
  u->add_weight(1.0);
  v1::ComponentPrior* y = spec.add_output_priors();
  y->add_weight(10.0);
  y->add_target(0.0);
  return spec;
}

// The same problem with the model written out, time-invariant, as any linear client would.
v1::ProblemSpec AffineLinearSpec(int horizon, const std::vector<double>& x0) {
  v1::ProblemSpec spec = AffineTemplate(horizon);
  spec.mutable_initial_state()->mutable_mean()->Assign(x0.begin(), x0.end());
  v1::Model* m = spec.mutable_model();
  m->set_num_states(2);
  m->set_num_inputs(1);
  m->set_num_outputs(1);
  const auto matrix = [](v1::Matrix* out, int rows, int cols, const double* data) {
    out->set_rows(rows);
    out->set_cols(cols);
    out->mutable_data()->Add(data, data + rows * cols);
  };
  matrix(m->add_a(), 2, 2, kA);
  matrix(m->add_b(), 2, 1, kB);
  matrix(m->add_c(), 1, 2, kC);
  m->add_state_offset(kStateOffset[0]);
  m->add_state_offset(kStateOffset[1]);
  m->add_output_offset(kOutputOffset);
  return spec;
}

TEST_F(ServiceTest, NonlinearSessionOfALinearPlantPlansAsTheLinearSession) {
  constexpr int kN = 20;
  auto session = NonlinearSession::Create(*client_, AffineModel(), AffineTemplate(kN));
  ASSERT_THAT(session, IsOk());
  std::vector<double> x = {1.0, 0.0};
  for (int period = 0; period < 3; ++period) {
    absl::StatusOr<NonlinearPlan> plan = (*session)->Step(x);
    ASSERT_THAT(plan, IsOk());
    ASSERT_TRUE(plan->has_plan);
    absl::StatusOr<v1::SolveResult> linear = client_->SolveOnce(AffineLinearSpec(kN, x));
    ASSERT_THAT(linear, IsOk());
    ASSERT_EQ(linear->status(), v1::SOLVE_STATUS_CONVERGED);
    // The same problem, stored per step on one side and time-invariant on the other, so
    // solved along other arithmetic (and warm from period 1 on): equal to the solver's
    // tolerance.
    constexpr double tolerance = 1e-6;
    EXPECT_LT(MaxAbsDifference(plan->inputs, {linear->inputs().begin(), linear->inputs().end()}), tolerance)
        << "period " << period;
    EXPECT_LT(MaxAbsDifference(plan->states, {linear->states().begin(), linear->states().end()}), tolerance);
    EXPECT_LT(MaxAbsDifference(plan->outputs, {linear->outputs().begin(), linear->outputs().end()}), tolerance);
    // A linear plant is its own linearisation: the plan is a trajectory of it up to rounding.
    EXPECT_LT(plan->report.model_defect, 1e-9);
    x = {plan->states[2], plan->states[3]};
  }
}

// Points where nothing is zero that would hide a wrong entry.
std::vector<std::vector<double>> BicyclePoints() {
  return {{3.0, -0.4, 0.3, 4.0, 1.2, 0.2}, {17.0, 1.1, -0.6, 5.0, -0.5, -0.45}, {40.0, -1.5, 1.0, 2.0, 0.3, 0.05}};
}

TEST(NonlinearSessionJacobians, FiniteDifferencesAgreeWithTheAnalyticJacobians) {
  const ex::BicycleScenario scenario;
  const NonlinearModel bicycle = ex::BicycleModel(scenario, /*analytic_jacobians=*/true);
  for (const std::vector<double>& p : BicyclePoints()) {
    const std::vector<double> x(p.begin(), p.begin() + 4), u(p.begin() + 4, p.end());
    absl::StatusOr<LinearisedStep> analytic = Linearise(bicycle, 0, x, u);
    absl::StatusOr<LinearisedStep> differences = Linearise(bicycle, 0, x, u, /*force_finite_differences=*/true);
    ASSERT_THAT(analytic, IsOk());
    ASSERT_THAT(differences, IsOk());
    // Central differences with h = 1e-6·(1 + |x|): about 1e-10 relative error on these scales.
    EXPECT_LT(MaxAbsDifference(analytic->A, differences->A), 1e-8);
    EXPECT_LT(MaxAbsDifference(analytic->B, differences->B), 1e-8);
    EXPECT_LT(MaxAbsDifference(analytic->C, differences->C), 1e-8);
    EXPECT_LT(MaxAbsDifference(analytic->c, differences->c), 1e-7);  // c = f − A x̄ − B ū: |x̄| ≈ 40
    EXPECT_LT(MaxAbsDifference(analytic->d, differences->d), 1e-7);
    EXPECT_THAT(CheckJacobians(bicycle, 0, x, u), IsOk());
  }
  // The race model: stiff (ψ v⁴ / ℓ² ≈ 6e4 before scaling) and time-varying (curvature per step).
  const ex::Track track = ex::DemoTrack();
  const NonlinearModel race = ex::RaceModel(track, ex::Vehicle{}, 100);
  for (const std::int64_t t : {0, 12, 57}) {
    const std::vector<double> x = {0.003, 0.2, 0.8, 0.4, 0.1, 2.0}, u = {0.7, -0.3};
    EXPECT_THAT(CheckJacobians(race, t, x, u, 1e-6), IsOk()) << "t = " << t;
  }
}

TEST(NonlinearSessionJacobians, AWrongAnalyticEntryIsNamed) {
  const ex::BicycleScenario scenario;
  NonlinearModel model = ex::BicycleModel(scenario);
  const auto right = model.transition_u;
  model.transition_u = [right](std::int64_t t, const std::vector<double>& x, const std::vector<double>& u) {
    std::vector<double> B = right(t, x, u);
    B[2 * 2 + 1] *= 0.5;  // ∂ψ⁺/∂δ halved
    return B;
  };
  const std::vector<double> x = {3.0, -0.4, 0.3, 4.0}, u = {1.2, 0.2};
  EXPECT_THAT(CheckJacobians(model, 7, x, u), StatusIs(absl::StatusCode::kInvalidArgument,
                                                       AllOf(HasSubstr("NonlinearModel.transition_u (∂f/∂u) at t = 7"),
                                                             HasSubstr("entry (2, 1)"), HasSubstr("∂f_2/∂u_1"))));
}

TEST_F(ServiceTest, NonlinearSessionRefusesAWrongJacobianBeforeCreatingASession) {
  const ex::BicycleScenario scenario;
  NonlinearModel model = ex::BicycleModel(scenario);
  const auto right = model.transition_x;
  model.transition_x = [right](std::int64_t t, const std::vector<double>& x, const std::vector<double>& u) {
    std::vector<double> A = right(t, x, u);
    A[0 * 4 + 3] = -A[0 * 4 + 3];  // ∂px⁺/∂v with the wrong sign: 0.1 at the start (heading 0)
    return A;
  };
  auto session = NonlinearSession::Create(*client_, model, ex::BicycleSpec(scenario));
  EXPECT_THAT(session, StatusIs(absl::StatusCode::kInvalidArgument,
                                AllOf(HasSubstr("NonlinearModel.transition_x (∂f/∂x)"), HasSubstr("entry (0, 3)"),
                                      HasSubstr("∂f_0/∂x_3"), HasSubstr("is -0.1"))));
  model = ex::BicycleModel(scenario);
  const auto right_output = model.output_x;
  model.output_x = [right_output](std::int64_t t, const std::vector<double>& x) {
    std::vector<double> C = right_output(t, x);
    C[2 * 4 + 0] = 0.0;  // ∂e/∂px forgotten: the path's slope, 0.19 at px = 0
    return C;
  };
  session = NonlinearSession::Create(*client_, model, ex::BicycleSpec(scenario));
  EXPECT_THAT(session, StatusIs(absl::StatusCode::kInvalidArgument,
                                AllOf(HasSubstr("NonlinearModel.output_x (∂h/∂x)"), HasSubstr("entry (2, 0)"))));
  absl::StatusOr<std::vector<v1::SessionInfo>> sessions = client_->ListSessions();
  ASSERT_THAT(sessions, IsOk());
  EXPECT_TRUE(sessions->empty()) << "refused on the client, before anything reached the server";
}

TEST_F(ServiceTest, NonlinearSessionFiniteDifferencesPlanAsTheAnalyticJacobians) {
  ex::BicycleScenario scenario;
  scenario.max_periods = 25;  // into the first obstacle's influence (from period 7 on)
  NonlinearSessionOptions options;
  absl::StatusOr<ex::BicycleRun> analytic = ex::RunBicycle(*client_, scenario, options, /*analytic_jacobians=*/true);
  absl::StatusOr<ex::BicycleRun> differences = ex::RunBicycle(*client_, scenario, options, false);
  ASSERT_THAT(analytic, IsOk());
  ASSERT_THAT(differences, IsOk());
  ASSERT_EQ(analytic->periods.size(), differences->periods.size());
  for (std::size_t p = 0; p < analytic->periods.size(); ++p) {
    EXPECT_LT(MaxAbsDifference(analytic->periods[p].input, differences->periods[p].input), 1e-5) << "period " << p;
  }
}

TEST_F(ServiceTest, NonlinearSessionRefusesBadSpecsOptionsAndStepsNamingTheField) {
  const ex::BicycleScenario scenario;
  const NonlinearModel model = ex::BicycleModel(scenario);
  v1::ProblemSpec spec = ex::BicycleSpec(scenario);
  spec.mutable_model()->add_a();
  EXPECT_THAT(NonlinearSession::Create(*client_, model, spec),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("spec.model: a, b, c")));
  spec = ex::BicycleSpec(scenario);
  spec.mutable_output_priors()->RemoveLast();
  EXPECT_THAT(NonlinearSession::Create(*client_, model, spec),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("spec.output_priors: expected 4")));
  spec = ex::BicycleSpec(scenario);
  spec.mutable_keep_out()->set_second_output(4);
  EXPECT_THAT(NonlinearSession::Create(*client_, model, spec),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("spec.keep_out.second_output = 4")));
  NonlinearSessionOptions options;
  options.region.state_radius = {1.0, 1.0};
  EXPECT_THAT(NonlinearSession::Create(*client_, model, ex::BicycleSpec(scenario), options),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("NonlinearSessionOptions.region.state_radius: expected 4 values")));
  InitialGuess guess;
  guess.inputs = {0.0};
  EXPECT_THAT(NonlinearSession::Create(*client_, model, ex::BicycleSpec(scenario), {}, guess),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("InitialGuess")));

  auto session = NonlinearSession::Create(*client_, model, ex::BicycleSpec(scenario));
  ASSERT_THAT(session, IsOk());
  EXPECT_THAT((*session)->Step({0.0, 0.0, 0.0}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("measured_state: expected 4")));
  v1::PriorUpdate update;
  update.add_outputs()->set_index(4);
  EXPECT_THAT((*session)->Step(scenario.start, update),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("update.outputs: index 4")));
  // The server's own refusal comes back with the period and linearisation it belongs to.
  update.Clear();
  v1::PriorUpdate::Entry* entry = update.add_inputs();
  entry->set_index(1);
  entry->mutable_prior()->set_kind(v1::PRIOR_KIND_BOX);
  entry->mutable_prior()->add_lower(1.0);
  entry->mutable_prior()->add_upper(-1.0);
  EXPECT_THAT((*session)->Step(scenario.start, update),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("period 0, linearisation 0: step.update")));
  absl::StatusOr<NonlinearPlan> plan = (*session)->Step(scenario.start);
  ASSERT_THAT(plan, IsOk()) << "a refused step leaves the session usable";
  EXPECT_TRUE(plan->has_plan);
}

// SQP (max_linearisations > 1) re-linearises along each plan until it stops moving: the
// plan is then a trajectory of the nonlinear model, not only of its linearisation.
TEST_F(ServiceTest, NonlinearSessionSqpSettlesOnATrajectoryOfTheNonlinearModel) {
  const ex::BicycleScenario scenario;
  NonlinearSessionOptions options;
  options.max_linearisations = 30;
  options.step_tolerance = 1e-8;
  const NonlinearModel model = ex::BicycleModel(scenario);
  auto session = NonlinearSession::Create(*client_, model, ex::BicycleSpec(scenario), options);
  ASSERT_THAT(session, IsOk());
  absl::StatusOr<NonlinearPlan> plan = (*session)->Step(scenario.start);
  ASSERT_THAT(plan, IsOk());
  ASSERT_TRUE(plan->has_plan);
  EXPECT_TRUE(plan->report.converged) << plan->report.linearisations << " linearisations";
  EXPECT_GT(plan->report.linearisations, 2) << "the start (state held, inputs zero) is far from the plan";
  EXPECT_LT(plan->report.model_defect, 1e-7);
  ASSERT_EQ(plan->report.solve_passes.size(), static_cast<std::size_t>(plan->report.linearisations));
  // The plan's inputs drive the true model along the plan's states.
  std::vector<double> x = scenario.start;
  for (int n = 0; n < scenario.horizon; ++n) {
    x = model.transition(n, x, {plan->inputs[2 * n], plan->inputs[2 * n + 1]});
    EXPECT_LT(MaxAbsDifference(
                  x, std::vector<double>(plan->states.begin() + 4 * (n + 1), plan->states.begin() + 4 * (n + 2))),
              1e-6)
        << "step " << n + 1;
  }
}

// The bicycle's closed loop (real-time iteration, one linearisation per period).
class BicycleClosedLoop : public ServiceTest {
 protected:
  static absl::StatusOr<ex::BicycleRun> Run(Client& client, v1::WarmStart warm_start) {
    NonlinearSessionOptions options;
    options.warm_start = warm_start;
    return ex::RunBicycle(client, ex::BicycleScenario{}, options);
  }
};

TEST_F(BicycleClosedLoop, KeepsEveryBoundTracksThePathAndReachesTheGoal) {
  const ex::BicycleScenario s;
  absl::StatusOr<ex::BicycleRun> run = Run(*client_, v1::WARM_START_SHIFT);
  ASSERT_THAT(run, IsOk());
  ASSERT_TRUE(run->reached_goal) << "px = " << run->final_state[0] << " after " << run->periods.size() << " periods";
  double least_clearance = 1e300, least_plan_clearance = 1e300;
  for (const ex::BicyclePeriod& p : run->periods) {
    SCOPED_TRACE(absl::StrCat("period ", p.period));
    // Inputs: hard boxes, applied as planned.
    EXPECT_GE(p.input[0], s.min_acceleration - 1e-9);
    EXPECT_LE(p.input[0], s.max_acceleration + 1e-9);
    EXPECT_LE(std::abs(p.input[1]), s.max_steering + 1e-9);
    // The speed bound holds from step 1 on (x[0] = the start state, below it).
    EXPECT_LE(p.state[3], s.speed_limit + 1e-6);
    // The obstacles' true shapes, for the car and for every plan: the server keeps plans out
    // of the regions enlarged by the margin, and the car moves as planned up to the
    // linearisation's second-order error, which the margin covers.
    EXPECT_GE(p.clearance, -1e-6);
    EXPECT_GE(p.plan_clearance, -1e-6);
    EXPECT_LE(p.max_violation, 1e-4);
    least_clearance = std::min(least_clearance, p.clearance);
    least_plan_clearance = std::min(least_plan_clearance, p.plan_clearance);
  }
  // The obstacles matter: the path runs through the first one, and the car skirts it.
  EXPECT_LT(least_clearance, s.margin + 0.05);
  EXPECT_GE(least_clearance, s.margin - 1e-3) << "the car keeps the margin (up to the second-order error)";
  // Tracking: the last 2 s (10 m, after 19 m without obstacles) stay within 5 cm of the
  // path. The path's curvature (up to 0.024 1/m) against the steering weight leaves about
  // 1.3 cm with these weights; 5 cm is 1/30 of the path's amplitude, and a car that had not
  // settled after the last obstacle (0.5 m off there) would miss it.
  double last_error = 0.0;
  for (std::size_t p = run->periods.size() - 20; p < run->periods.size(); ++p) {
    last_error = std::max(last_error, std::abs(run->periods[p].lateral_error));
  }
  EXPECT_LT(last_error, 0.05);
  EXPECT_NEAR(run->final_state[3], s.speed_limit, 1e-3) << "at the speed limit (the reference is above it)";
  std::printf(
      "bicycle: %zu periods to the goal, least clearance %.4f m (car), %.4f m (plans), last 2 s lateral "
      "error <= %.4f m\n",
      run->periods.size(), least_clearance, least_plan_clearance, last_error);
}

TEST_F(BicycleClosedLoop, WarmPeriodsTakeAFractionOfTheColdPasses) {
  absl::StatusOr<ex::BicycleRun> warm = Run(*client_, v1::WARM_START_SHIFT);
  absl::StatusOr<ex::BicycleRun> cold = Run(*client_, v1::WARM_START_COLD);
  ASSERT_THAT(warm, IsOk());
  ASSERT_THAT(cold, IsOk());
  const auto reports = [](const ex::BicycleRun& run) {
    std::vector<PeriodReport> r;
    for (const ex::BicyclePeriod& p : run.periods) r.push_back(p.report);
    return r;
  };
  constexpr int kSettle = 5;  // the first period is cold in both runs; the next few settle from the start
  const ex::PeriodSummary w = ex::Summarise(reports(*warm), kSettle), c = ex::Summarise(reports(*cold), kSettle);
  ex::PrintWarmVsCold(stdout, w, c);
  // Medians: a cold run has a few degenerate solves that run to the iteration cap (5000
  // passes), which would decide a mean. A cold solve with the speed bound active needs
  // 15-30 passes, a warm one 2-3 (measured medians 2 and 17; means 3.1 and 101).
  EXPECT_LT(w.median_passes, 0.5 * c.median_passes);
  EXPECT_EQ(w.first_passes, c.first_passes) << "period 0 is cold in both";
}

// The example programs, as a user runs them: against a nupmpc-server of their own.
class ApiExamplePrograms : public ::testing::Test {
 protected:
  void SetUp() override {
    port_ = FreeLoopbackPort();
    ASSERT_GT(port_, 0);
    server_ =
        std::make_unique<ServerProcess>(NUPMPC_SERVER_BINARY, port_, std::vector<std::string>{"--log_level=warn"});
    auto channel = nupmpc::OpenChannel(server_->target());
    ASSERT_TRUE(channel->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(30)));
  }
  // stdout and stderr of `binary --server=... flags`, and its exit status.
  std::pair<int, std::string> Run(const std::string& binary, const std::string& flags) {
    const std::string command = absl::StrCat(binary, " --server=", server_->target(), " ", flags, " 2>&1");
    FILE* out = popen(command.c_str(), "r");
    if (out == nullptr) return {-1, ""};
    std::string text;
    char buffer[4096];
    for (std::size_t n; (n = fread(buffer, 1, sizeof buffer, out)) > 0;) text.append(buffer, n);
    const int status = pclose(out);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text};
  }
  int port_ = 0;
  std::unique_ptr<ServerProcess> server_;
};

TEST_F(ApiExamplePrograms, BicyclePrintsPeriodsAndWarmVsCold) {
  const auto [code, text] = Run(NUPMPC_API_EXAMPLE_BICYCLE, "--periods=40");
  EXPECT_EQ(code, 0) << text;
  EXPECT_THAT(text, HasSubstr("period   lin  passes"));
  EXPECT_THAT(text, HasSubstr("goal NOT reached after 40 periods"));  // 40 periods are 20 m of 75
  EXPECT_THAT(text, HasSubstr("warm/cold: passes per period"));
}

TEST_F(ApiExamplePrograms, RaceTrackPrintsTheLap) {
  const auto [code, text] = Run(NUPMPC_API_EXAMPLE_RACE_TRACK, "--steps=40 --max_linearisations=20");
  EXPECT_EQ(code, 0) << text;
  EXPECT_THAT(text, HasSubstr("race track K=40"));
  EXPECT_THAT(text, HasSubstr("linearisations=20"));
  EXPECT_THAT(text, HasSubstr("passes: first (cold) solve"));
}

}  // namespace
}  // namespace nupmpc::testing
