// Data-driven GP-MPC through the v1 API ([Nghiem] §V's tanh plant): FitGpModel finds the
// plant's noise level and matches the core fit; a GP session streamed through Control
// gives, step by step, exactly the plans of a core linGP-SCP on the same model, with the
// chance constraints met under the exact GP; references change per step; a spec without a
// kernel is fitted on creation; bad specs and steps are refused naming the field and leave
// the session as it was, every spec rule before the O(P³) set-up; requests at the point
// limit free their worker soon after their deadline; ±Infinity output bounds are solved.
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <utility>

#include "core/examples/scenarios/gp_tanh.h"
#include "core/gp/hyperparameter_fit.h"
#include "core/gp/lingp_scp.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/convert/gp_conversion.h"
#include "server/convert/gp_model_cache.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;

// The logged experiment behind examples::TanhTrainingData(points, seed).
v1::GpModel LoggedModel(int points, std::uint32_t seed) {
  const examples::TanhExperiment e = examples::RunTanhExperiment(points + 1, seed);
  v1::GpModel model;
  model.set_output_lags(1);
  model.set_input_lags(0);
  model.mutable_logged_outputs()->Add(e.y.data(), e.y.data() + e.y.size());
  model.mutable_logged_inputs()->Add(e.u.data(), e.u.data() + e.u.size());
  return model;
}

gp::SeArdKernel FittedKernel() {
  auto data = examples::TanhTrainingData(200, 1);
  gp::SeArdKernel start;
  start.signal_variance = 1.0;
  start.length_scales = Eigen::Vector2d(1.0, 1.0);
  start.noise_variance = 0.01;
  auto fit = gp::FitHyperparameters(data->regressors, data->targets, start);
  EXPECT_TRUE(fit.ok() && fit->converged);
  return fit->kernel;
}

void SetKernel(const gp::SeArdKernel& kernel, v1::GpModel* model) {
  v1::GpKernel* k = model->mutable_kernel();
  k->set_signal_variance(kernel.signal_variance);
  k->set_noise_variance(kernel.noise_variance);
  for (Eigen::Index i = 0; i < kernel.length_scales.size(); ++i) k->add_length_scales(kernel.length_scales(i));
}

// MPC (21) of the example as a spec, on `points` training pairs.
v1::ProblemSpec TanhSpec(int points, const gp::SeArdKernel* kernel) {
  const gp::GpMpcProblem p = examples::TanhMpcProblem();
  v1::ProblemSpec spec;
  v1::GpMpc* g = spec.mutable_gp();
  *g->mutable_model() = LoggedModel(points, 2);
  if (kernel != nullptr) SetKernel(*kernel, g->mutable_model());
  g->set_horizon(p.horizon);
  g->set_output_weight(p.output_weight);
  g->set_input_change_weight(p.input_change_weight);
  g->set_input_min(p.input_min);
  g->set_input_max(p.input_max);
  g->set_rate_min(p.rate_min);
  g->set_rate_max(p.rate_max);
  g->set_output_min(p.output_min);
  g->set_output_max(p.output_max);
  g->set_sigma_multiple(p.sigma_multiple);
  g->set_terminal_tolerance(p.terminal_tolerance);
  g->add_reference(examples::TanhReference(0));
  return spec;
}

v1::Step WindowStep(double y, double u) {
  v1::Step step;
  step.add_state(y);  // y[t-1]
  step.add_state(u);  // u[t-1]
  return step;
}

TEST_F(ServiceTest, FitGpModelFindsTheNoiseLevel) {
  v1::FitGpModelRequest request;
  *request.mutable_model() = LoggedModel(300, 1);
  absl::StatusOr<v1::FitGpModelResponse> fit = client_->FitGpModel(request);
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_TRUE(fit->converged());
  EXPECT_EQ(fit->num_points(), 300u);
  EXPECT_LT(fit->negative_log_likelihood(), fit->initial_negative_log_likelihood());
  // The plant's measurement noise has std 0.025; the fit's residual is of that size.
  EXPECT_NEAR(std::sqrt(fit->kernel().noise_variance()), examples::kTanhNoiseStd, 0.01);
  EXPECT_LT(fit->training_rmse(), 2 * examples::kTanhNoiseStd);
  ASSERT_EQ(fit->kernel().length_scales_size(), 2);

  // The same fit in the core, from the start the server reports, gives the same kernel.
  auto data = examples::TanhTrainingData(300, 1);
  gp::SeArdKernel start;
  start.signal_variance = fit->initial_kernel().signal_variance();
  start.noise_variance = fit->initial_kernel().noise_variance();
  start.length_scales = Eigen::Vector2d(fit->initial_kernel().length_scales(0), fit->initial_kernel().length_scales(1));
  auto core_fit = gp::FitHyperparameters(data->regressors, data->targets, start);
  ASSERT_TRUE(core_fit.ok());
  EXPECT_EQ(core_fit->kernel.noise_variance, fit->kernel().noise_variance());
  EXPECT_EQ(core_fit->kernel.length_scales(0), fit->kernel().length_scales(0));
  EXPECT_EQ(core_fit->negative_log_likelihood, fit->negative_log_likelihood());
}

TEST_F(ServiceTest, GpSessionStreamsTheCoreScpPlans) {
  const gp::SeArdKernel kernel = FittedKernel();
  const v1::ProblemSpec spec = TanhSpec(200, &kernel);
  absl::StatusOr<std::unique_ptr<Session>> session = client_->OpenSession(spec);
  ASSERT_TRUE(session.ok()) << session.status();

  // The reference: a core linGP-SCP on the same training data and kernel.
  auto data = examples::TanhTrainingData(200, 2);
  auto model = gp::GpModel::Create(data->regressors, data->targets, kernel);
  ASSERT_TRUE(model.ok());
  auto scp = gp::LinGpScp::Create(&*model, examples::TanhMpcProblem());
  ASSERT_TRUE(scp.ok());

  const gp::GpMpcProblem p = examples::TanhMpcProblem();
  constexpr int kSteps = 20, kReferenceChange = 10;
  double x = 0.0, y = 0.0, u = 0.0;
  for (int t = 0; t < kSteps; ++t) {
    SCOPED_TRACE(t);
    const double r = t < kReferenceChange ? -0.5 : -0.2;
    v1::Step step = WindowStep(y, u);
    if (t == kReferenceChange) step.add_reference(r);  // kept for the later steps
    absl::StatusOr<v1::SolveResult> result = (*session)->Step(step);
    ASSERT_TRUE(result.ok()) << result.status();

    (*scp)->ShiftWarmStart();
    gp::ScpPlan plan;
    auto core = (*scp)->Solve(Eigen::VectorXd::Constant(1, y), Eigen::VectorXd::Constant(1, u),
                              Eigen::VectorXd::Constant(1, r), &plan);
    ASSERT_TRUE(core.ok()) << core.status();

    EXPECT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED);
    EXPECT_EQ(result->warm_started(), t > 0);
    EXPECT_EQ(result->linearisations(), static_cast<unsigned>(core->iterations));
    EXPECT_EQ(result->iterations(), static_cast<unsigned>(core->inner_passes));
    EXPECT_LE(result->max_violation(), 1e-9) << "chance/terminal constraints under the exact GP";
    ASSERT_EQ(result->inputs_size(), p.horizon);
    ASSERT_EQ(result->outputs_size(), p.horizon + 1);
    ASSERT_EQ(result->output_stddev_size(), p.horizon + 1);
    ASSERT_EQ(result->states_size(), 2 * (p.horizon + 1));
    EXPECT_EQ(result->outputs(0), y);
    EXPECT_EQ(result->output_stddev(0), 0.0);
    for (int n = 0; n < p.horizon; ++n) {
      EXPECT_EQ(result->inputs(n), plan.inputs(n)) << "u[t+" << n << "]";
      EXPECT_EQ(result->outputs(n + 1), plan.means(n));
      EXPECT_EQ(result->output_stddev(n + 1), plan.sigmas(n));
      EXPECT_GT(result->output_stddev(n + 1), 0.0);
      // The window at step n+1 holds ȳ[t+n] and u[t+n].
      EXPECT_EQ(result->states(2 * (n + 1)), plan.means(n));
      EXPECT_EQ(result->states(2 * (n + 1) + 1), plan.inputs(n));
      EXPECT_GE(result->inputs(n), p.input_min);
      EXPECT_LE(result->inputs(n), p.input_max);
    }
    EXPECT_LE(std::abs(result->inputs(0) - u), p.rate_max + 1e-12);
    u = result->inputs(0);
    x = examples::TanhPlantStep(x, u);
    y = x;  // noise-free plant: the loop is deterministic
  }
  EXPECT_NEAR(y, -0.2, 0.1) << "the loop follows the changed reference";
  EXPECT_TRUE((*session)->Close().ok());
}

TEST_F(ServiceTest, GpSpecWithoutKernelIsFittedOnCreation) {
  const v1::ProblemSpec spec = TanhSpec(100, nullptr);
  absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
  ASSERT_TRUE(once.ok()) << once.status();
  EXPECT_EQ(once->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_LE(once->max_violation(), 1e-9);
  ASSERT_EQ(once->inputs_size(), examples::TanhMpcProblem().horizon);
  // From rest at y = 0 towards -0.5 the plan moves the input, within the rate limit.
  EXPECT_GT(std::abs(once->inputs(0)), 0.01);
  EXPECT_LE(std::abs(once->inputs(0)), 0.5 + 1e-12);
}

TEST_F(ServiceTest, GpSolvesHonourTheTimeLimit) {
  const gp::SeArdKernel kernel = FittedKernel();
  absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(TanhSpec(200, &kernel));
  ASSERT_TRUE(created.ok()) << created.status();
  v1::Step step = WindowStep(0.3, 0.0);
  step.set_time_limit_ms(1e-3);  // over before the first SCP iteration
  absl::StatusOr<v1::SolveResult> r = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->status(), v1::SOLVE_STATUS_TIME_LIMIT);
  EXPECT_EQ(r->linearisations(), 0u);
  // No SCP iteration for this state was accepted: no plan (the cold start is not one).
  EXPECT_FALSE(r->has_plan());
  EXPECT_EQ(r->inputs_size(), 0);
  EXPECT_EQ(r->outputs_size(), 0);
  // Without the limit the same session converges.
  step.set_time_limit_ms(0.0);
  r = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_TRUE(r->has_plan());
  EXPECT_EQ(r->inputs_size(), 12);
}

TEST(GpModelCache, SessionsOfOneModelShareItWhileAnyHoldsIt) {
  server::GpModelCache cache;
  auto data = examples::TanhTrainingData(60, 2);
  ASSERT_TRUE(data.ok());
  int builds = 0;
  const auto make = [&]() -> absl::StatusOr<gp::GpModel> {
    ++builds;
    return gp::GpModel::Create(data->regressors, data->targets, FittedKernel());
  };
  auto a = cache.GetOrCreate("model a", make);
  auto b = cache.GetOrCreate("model a", make);
  auto c = cache.GetOrCreate("model c", make);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->get(), b->get());
  EXPECT_NE(a->get(), c->get());
  EXPECT_EQ(builds, 2);
  EXPECT_EQ(cache.live_models(), 2);
  a->reset();
  b->reset();
  EXPECT_EQ(cache.live_models(), 1) << "nobody holds model a any more";
  ASSERT_TRUE(cache.GetOrCreate("model a", make).ok());
  EXPECT_EQ(builds, 3) << "a model nobody held is built again";
  const auto failing = []() -> absl::StatusOr<gp::GpModel> { return absl::InvalidArgumentError("bad data"); };
  EXPECT_EQ(cache.GetOrCreate("model d", failing).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(cache.live_models(), 1) << "a failed build is not cached (model c alone is held)";
  ASSERT_TRUE(cache.GetOrCreate("model d", make).ok()) << "nor does it stop the next build of its key";
}

// Ten sessions on the same data and kernel hold one factorised GP between them: the
// server's memory grows by about one model, not ten.
TEST_F(ServiceTest, GpSessionsOfTheSameModelShareItsFactorisation) {
  const gp::SeArdKernel kernel = FittedKernel();
  const v1::ProblemSpec spec = TanhSpec(1000, &kernel);  // K and its eigenbasis: about 16 MB while built
  const auto rss = [&]() {
    absl::StatusOr<v1::GetServerInfoResponse> info = client_->GetServerInfo();
    EXPECT_TRUE(info.ok());
    return static_cast<double>(info->resident_memory_bytes());
  };
  const double before = rss();
  if (before == 0.0) GTEST_SKIP() << "this platform reports no resident memory";
  absl::StatusOr<v1::CreateSessionResponse> first = client_->CreateSession(spec);
  ASSERT_TRUE(first.ok()) << first.status();
  const double one = rss() - before;
  for (int i = 0; i < 9; ++i) ASSERT_TRUE(client_->CreateSession(spec).ok());
  const double nine_more = rss() - before - one;
  EXPECT_GT(one, 4e6) << "the first session holds the 1000-point model (8 MB Cholesky factor)";
  EXPECT_LT(nine_more, 0.5 * one) << "nine more sessions of the same model took " << nine_more / 1e6
                                  << " MB; the first took " << one / 1e6 << " MB";
}

// At the server's point limit (5,000 training pairs) every O(P³) phase of a GP request
// runs in blocks with a deadline check between them (kernel matrix, low-rank factor,
// Cholesky factor, the likelihood's inverse and gradient, each L-BFGS evaluation), so an
// abandoned request frees its worker within about one block: a SolveOnce queued behind it on
// a one-worker server is answered soon after the deadline, although the work itself runs
// for many seconds (an uninterrupted likelihood evaluation alone is about P³ multiply-adds).
// The bound asserted, 2 s after the deadline, is generous for a shared or instrumented
// machine; the message must say the set-up was stopped inside, not refused before it.
TEST_F(ServiceTest, GpRequestsAtThePointLimitFreeTheirWorkerAtTheDeadline) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.worker_threads = 1;
  StartServer(options);
  const int points = options.size_limits.max_gp_points;
  constexpr double kDeadlineS = 0.3, kAfterDeadlineS = 2.0;
  const v1::ProblemSpec quick = SpecOrDie(LoadInstanceOrDie("masses_N30").problem);
  ASSERT_TRUE(client_->SolveOnce(quick).ok());  // warm: connection and code paths
  const auto solve_soon_after = [&](const char* what, const std::function<absl::Status(Client&)>& abandoned) {
    // The server sees the call's deadline; the client gets DEADLINE_EXCEEDED at it.
    Client impatient(target_, std::chrono::milliseconds(static_cast<int>(kDeadlineS * 1000)));
    const auto start = std::chrono::steady_clock::now();
    const absl::Status status = abandoned(impatient);
    EXPECT_EQ(status.code(), absl::StatusCode::kDeadlineExceeded) << what << ": " << status;
    absl::StatusOr<v1::SolveResult> solve = client_->SolveOnce(quick);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ASSERT_TRUE(solve.ok()) << what << ": " << solve.status();
    EXPECT_LT(seconds, kDeadlineS + kAfterDeadlineS) << what << ": the solve waited for the abandoned request";
    std::printf("%s at %d points: the next solve was answered %.3f s after the deadline\n", what, points,
                seconds - kDeadlineS);
  };
  const gp::SeArdKernel kernel = FittedKernel();
  solve_soon_after("CreateSession, kernel given",
                   [&](Client& c) { return c.CreateSession(TanhSpec(points, &kernel)).status(); });
  solve_soon_after("CreateSession, kernel fitted",
                   [&](Client& c) { return c.CreateSession(TanhSpec(points, nullptr)).status(); });
  v1::FitGpModelRequest request;
  *request.mutable_model() = LoggedModel(points, 1);
  solve_soon_after("FitGpModel", [&](Client& c) { return c.FitGpModel(request).status(); });
}

// In process, the message of a stopped set-up says where it stopped (the client of an
// abandoned call never sees it), and a set-up stopped by a deadline or cancellation caches
// nothing: the next request for the same model builds it.
TEST(GpSetUp, AStoppedSetUpSaysHowFarItGotAndCachesNothing) {
  const server::SizeLimits limits;
  const gp::SeArdKernel kernel = FittedKernel();
  const v1::ProblemSpec spec = TanhSpec(limits.max_gp_points, &kernel);
  server::GpModelCache cache;
  gp::FitOptions deadline;
  deadline.max_seconds = 0.2;
  absl::StatusOr<std::unique_ptr<gp::GpMpcSession>> session = server::GpSessionFromSpec(spec, limits, &cache, deadline);
  ASSERT_EQ(session.status().code(), absl::StatusCode::kDeadlineExceeded) << session.status();
  EXPECT_THAT(std::string(session.status().message()), HasSubstr("spec.gp.model: GP set-up stopped in step"));
  EXPECT_EQ(cache.live_models(), 0);
  std::atomic<bool> cancel{true};
  gp::FitOptions cancelled;
  cancelled.cancel = &cancel;
  session = server::GpSessionFromSpec(spec, limits, &cache, cancelled);
  EXPECT_EQ(session.status().code(), absl::StatusCode::kCancelled) << session.status();
  v1::FitGpModelRequest request;
  *request.mutable_model() = LoggedModel(limits.max_gp_points, 1);
  v1::FitGpModelResponse response;
  const absl::Status fit = server::FitGpModel(request, limits, deadline, &response);
  EXPECT_EQ(fit.code(), absl::StatusCode::kDeadlineExceeded) << fit;
  EXPECT_THAT(std::string(fit.message()), HasSubstr("0 L-BFGS iterations on 5000 points"));
  // Small data: the same cache builds and keeps the model.
  const v1::ProblemSpec small = TanhSpec(60, &kernel);
  ASSERT_TRUE(server::GpSessionFromSpec(small, limits, &cache).ok());
}

// Every rule of a GP spec is checked before the O(P³) set-up: with the cancel flag already
// raised, a set-up step would answer CANCELLED, so INVALID_ARGUMENT naming the field shows
// the rule came first. The initial trust radius and ±Infinity output bounds used to be
// found (or refused) only by the SCP's set-up, after the factorisation, under an internal
// field name.
TEST(GpSetUp, EveryGpSpecRuleIsCheckedBeforeTheSetUp) {
  const server::SizeLimits limits;
  const gp::SeArdKernel kernel = FittedKernel();
  const v1::ProblemSpec good = TanhSpec(limits.max_gp_points, &kernel);
  std::atomic<bool> cancel{true};
  gp::FitOptions cancelled;
  cancelled.cancel = &cancel;
  const auto refused_first = [&](const v1::ProblemSpec& spec, const std::string& field) {
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<std::unique_ptr<gp::GpMpcSession>> session =
        server::GpSessionFromSpec(spec, limits, nullptr, cancelled);
    EXPECT_EQ(session.status().code(), absl::StatusCode::kInvalidArgument) << field << ": " << session.status();
    EXPECT_THAT(std::string(session.status().message()), HasSubstr(field));
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 2.0) << field;
  };
  v1::ProblemSpec s = good;
  s.mutable_gp()->mutable_scp()->set_initial_trust_radius(1e-300);
  refused_first(s, "spec.gp.scp.initial_trust_radius");
  s = good;
  s.mutable_gp()->set_sigma_multiple(-1.0);
  refused_first(s, "spec.gp.sigma_multiple");
  s = good;
  s.mutable_gp()->set_output_max(std::nan(""));
  refused_first(s, "spec.gp.output_max");
  s = good;
  s.mutable_gp()->set_input_min(-std::numeric_limits<double>::infinity());
  refused_first(s, "spec.gp.input_m");
  s = good;
  s.mutable_gp()->set_terminal_tolerance(std::nan(""));
  refused_first(s, "spec.gp.terminal_tolerance");
  s = good;
  s.mutable_gp()->mutable_model()->mutable_kernel()->set_signal_variance(0.0);
  refused_first(s, "spec.gp.model.kernel.signal_variance");
  // Infinite output bounds pass the rules: the set-up then starts (and is cancelled).
  s = good;
  s.mutable_gp()->set_output_min(-std::numeric_limits<double>::infinity());
  s.mutable_gp()->set_output_max(std::numeric_limits<double>::infinity());
  EXPECT_EQ(server::GpSessionFromSpec(s, limits, nullptr, cancelled).status().code(), absl::StatusCode::kCancelled);
}

// The .proto allows output_min/output_max of -Infinity/Infinity (no chance constraint on
// that side): accepted, and solved like any other session.
TEST_F(ServiceTest, InfiniteGpOutputBoundsAreAcceptedAndSolved) {
  const gp::SeArdKernel kernel = FittedKernel();
  const double inf = std::numeric_limits<double>::infinity();
  for (const auto& [low, high] : {std::pair{-inf, inf}, std::pair{-1.2, inf}, std::pair{-inf, 1.2}}) {
    v1::ProblemSpec spec = TanhSpec(100, &kernel);
    spec.mutable_gp()->set_output_min(low);
    spec.mutable_gp()->set_output_max(high);
    absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec);
    ASSERT_TRUE(created.ok()) << low << ".." << high << ": " << created.status();
    for (int t = 0; t < 3; ++t) {
      absl::StatusOr<v1::SolveResult> r = client_->Solve(created->session_id(), WindowStep(0.1 * t, 0.0));
      ASSERT_TRUE(r.ok()) << r.status();
      EXPECT_TRUE(r->status() == v1::SOLVE_STATUS_CONVERGED || r->status() == v1::SOLVE_STATUS_ITERATION_LIMIT)
          << v1::SolveStatus_Name(r->status());
      ASSERT_EQ(r->inputs_size(), 12);
      for (int n = 0; n < r->inputs_size(); ++n) EXPECT_TRUE(std::isfinite(r->inputs(n)));
      for (int n = 0; n < r->outputs_size(); ++n) EXPECT_TRUE(std::isfinite(r->outputs(n)));
      EXPECT_TRUE(std::isfinite(r->objective()));
    }
  }
}

TEST_F(ServiceTest, BadGpSpecsAreRefusedNamingTheField) {
  const gp::SeArdKernel kernel = FittedKernel();
  const v1::ProblemSpec good = TanhSpec(50, &kernel);
  const auto refused = [&](const v1::ProblemSpec& spec, const std::string& field) {
    absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec);
    ASSERT_FALSE(created.ok()) << field;
    EXPECT_EQ(created.status().code(), absl::StatusCode::kInvalidArgument) << created.status();
    EXPECT_THAT(std::string(created.status().message()), HasSubstr(field));
  };
  v1::ProblemSpec s = good;
  s.mutable_model()->set_num_states(1);
  refused(s, "spec.model");
  s = good;
  s.mutable_gp()->clear_model();
  refused(s, "spec.gp.model");
  s = good;
  s.mutable_gp()->mutable_model()->add_targets(1.0);  // both data forms
  refused(s, "spec.gp.model");
  s = good;
  s.mutable_gp()->mutable_model()->mutable_logged_inputs()->RemoveLast();
  refused(s, "spec.gp.model.logged_inputs");
  s = good;
  s.mutable_gp()->mutable_model()->set_logged_outputs(3, std::nan(""));
  refused(s, "spec.gp.model.logged_outputs[3]");
  s = good;
  s.mutable_gp()->mutable_model()->mutable_kernel()->add_length_scales(1.0);
  refused(s, "spec.gp.model.kernel.length_scales");
  s = good;
  s.mutable_gp()->mutable_model()->mutable_kernel()->set_noise_variance(-1.0);
  refused(s, "spec.gp.model.kernel.noise_variance");
  s = good;
  s.mutable_gp()->set_horizon(0);
  refused(s, "spec.gp.horizon");
  s = good;
  s.mutable_gp()->set_input_max(-2.0);
  refused(s, "spec.gp.input_max");
  s = good;
  s.mutable_gp()->set_rate_max(std::numeric_limits<double>::infinity());
  refused(s, "spec.gp.rate_max");
  s = good;
  s.mutable_gp()->set_output_weight(0.0);
  refused(s, "spec.gp.output_weight");
  s = good;
  s.mutable_gp()->add_reference(0.0);  // 2 values for H = 12
  refused(s, "spec.gp.reference");
  s = good;
  s.mutable_initial_state()->add_mean(0.0);
  refused(s, "spec.initial_state.mean");
  s = good;
  s.mutable_options()->set_algorithm(v1::ALGORITHM_IAKE);
  refused(s, "spec.options");
  s = good;
  s.mutable_gp()->mutable_scp()->set_penalty(-1.0);
  refused(s, "spec.gp.scp.penalty");

  // Too many training pairs for the server's limit.
  v1::FitGpModelRequest big;
  big.mutable_model()->mutable_regressors()->set_rows(5001);
  big.mutable_model()->mutable_regressors()->set_cols(2);
  big.mutable_model()->mutable_regressors()->mutable_data()->Resize(10002, 0.0);
  big.mutable_model()->mutable_targets()->Resize(5001, 0.0);
  absl::StatusOr<v1::FitGpModelResponse> fit = client_->FitGpModel(big);
  EXPECT_EQ(fit.status().code(), absl::StatusCode::kResourceExhausted) << fit.status();
  EXPECT_THAT(std::string(fit.status().message()), HasSubstr("model.regressors"));
  v1::FitGpModelRequest empty;
  EXPECT_THAT(std::string(client_->FitGpModel(empty).status().message()), HasSubstr("model"));
}

TEST_F(ServiceTest, RejectedGpStepsLeaveTheSessionAsItWas) {
  const gp::SeArdKernel kernel = FittedKernel();
  const v1::ProblemSpec spec = TanhSpec(100, &kernel);
  absl::StatusOr<v1::CreateSessionResponse> a = client_->CreateSession(spec);
  absl::StatusOr<v1::CreateSessionResponse> b = client_->CreateSession(spec);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->dimensions().num_states(), 2u);
  EXPECT_EQ(a->dimensions().horizon(), 12u);
  ASSERT_TRUE(client_->Solve(a->session_id(), WindowStep(0.0, 0.0)).ok());
  ASSERT_TRUE(client_->Solve(b->session_id(), WindowStep(0.0, 0.0)).ok());

  const auto refused = [&](const v1::Step& step, absl::StatusCode code, const std::string& field) {
    absl::StatusOr<v1::SolveResult> r = client_->Solve(a->session_id(), step);
    ASSERT_FALSE(r.ok()) << field;
    EXPECT_EQ(r.status().code(), code) << r.status();
    EXPECT_THAT(std::string(r.status().message()), HasSubstr(field));
  };
  v1::Step step = WindowStep(-0.1, 0.2);
  step.add_reference(-0.3);
  step.add_reference(-0.3);  // 2 values for H = 12
  refused(step, absl::StatusCode::kInvalidArgument, "step.reference");
  step = WindowStep(-0.1, 0.2);
  step.add_reference(std::nan(""));
  refused(step, absl::StatusCode::kInvalidArgument, "step.reference[0]");
  step = WindowStep(-0.1, 0.2);
  step.mutable_update()->set_shift(true);
  refused(step, absl::StatusCode::kFailedPrecondition, "step.update");
  step = WindowStep(-0.1, 0.2);
  step.add_state(0.0);
  refused(step, absl::StatusCode::kFailedPrecondition, "step.state");

  // After the refusals, session a answers exactly like b, which never saw them.
  v1::Step next = WindowStep(-0.1, 0.2);
  next.add_reference(-0.3);
  absl::StatusOr<v1::SolveResult> ra = client_->Solve(a->session_id(), next);
  absl::StatusOr<v1::SolveResult> rb = client_->Solve(b->session_id(), next);
  ASSERT_TRUE(ra.ok() && rb.ok());
  ASSERT_EQ(ra->inputs_size(), rb->inputs_size());
  for (int n = 0; n < ra->inputs_size(); ++n) EXPECT_EQ(ra->inputs(n), rb->inputs(n));
  EXPECT_EQ(ra->objective(), rb->objective());

  // A reference on a linear session is refused too.
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  absl::StatusOr<v1::CreateSessionResponse> linear = client_->CreateSession(SpecOrDie(inst.problem));
  ASSERT_TRUE(linear.ok());
  v1::Step with_reference;
  with_reference.add_reference(1.0);
  absl::StatusOr<v1::SolveResult> r = client_->Solve(linear->session_id(), with_reference);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(r.status().message()), HasSubstr("step.reference"));
}

}  // namespace
}  // namespace nupmpc::testing
