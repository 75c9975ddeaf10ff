// nupmpc-loadtest's machinery against an in-process server: closed-loop levels count
// every answer and match the requests sent; open-loop arrivals are answered or superseded,
// never lost; a queue that is too small for the streams answers RESOURCE_EXHAUSTED; the
// memory mode sees sessions grow and shrink the server's RSS. And the server side of the
// memory mode: an idle session compacted by the janitor continues bit-identically.
#include <cmath>
#include <thread>

#include "client/channel_factory.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "loadtest/core_baseline.h"
#include "loadtest/echo_process.h"
#include "loadtest/echo_server.h"
#include "loadtest/fleet_level.h"
#include "loadtest/idle_sessions.h"
#include "loadtest/load_level.h"
#include "loadtest/loadtest_report.h"
#include "loadtest/quantile.h"
#include "loadtest/transport_floor.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/session_registry.h"
#include "server/sessions/step_solver.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

struct Workload {
  v1::ProblemSpec spec;
  std::vector<std::vector<double>> states;
};

Workload MassesWorkload() {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  Workload w;
  w.spec = SpecOrDie(inst.problem);
  for (const Eigen::VectorXd& x : inst.closed_loop->x1) w.states.emplace_back(x.begin(), x.end());
  return w;
}

class LoadTest : public ServiceTest {
 protected:
  // A closed-loop level of the masses workload (after 0.1 s of warm-up).
  absl::StatusOr<loadtest::LevelReport> RunClosedLoop(int concurrency, double duration_s) {
    loadtest::LevelConfig config;
    config.concurrency = concurrency;
    config.duration_s = duration_s;
    config.warmup_s = 0.1;
    return loadtest::RunLevel(target_, Plan(/*closed_loop=*/true), config);
  }
  loadtest::StreamPlan Plan(bool closed_loop) const { return {&workload_.spec, &workload_.states, closed_loop}; }
  // A short level for the echo peers: 0.3 s after 0.05 s of warm-up.
  static loadtest::LevelConfig ShortLevel(int concurrency) {
    loadtest::LevelConfig config;
    config.concurrency = concurrency;
    config.duration_s = 0.3;
    config.warmup_s = 0.05;
    return config;
  }
  const Workload workload_ = MassesWorkload();
};

TEST_F(LoadTest, ClosedLoopLevelAnswersEveryRequestWithoutErrors) {
  absl::StatusOr<loadtest::LevelReport> r = RunClosedLoop(3, 0.6);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->tally.errors.empty());
  EXPECT_EQ(r->tally.superseded, 0u);  // closed loop never has two requests in flight
  EXPECT_EQ(r->tally.no_plan, 0u);     // the recorded masses states all get a plan (has_plan)
  EXPECT_GT(r->tally.latency_ms.size(), 30u);
  // Every counted request was answered (the streams drain before they stop).
  EXPECT_EQ(r->tally.sent, r->tally.latency_ms.size());
  // A round trip contains the server's solve.
  EXPECT_GE(r->p50_ms, r->solve_p50_ms);
  EXPECT_LE(r->p50_ms, r->p99_ms);
  EXPECT_LE(r->p99_ms, r->max_ms);
  EXPECT_NEAR(r->solves_per_s, r->tally.latency_ms.size() / r->measured_s, 1e-9);
  // The sequence warm-starts: on average far fewer iterations than cold solves (10).
  EXPECT_LT(r->mean_iterations, 8.0);
}

TEST_F(LoadTest, NewReferencesMoveEveryOutputsTargetAndChangeThePlan) {
  const v1::ProblemSpec& spec = workload_.spec;
  const v1::PriorUpdate first = loadtest::MovingReferences(spec, 1), second = loadtest::MovingReferences(spec, 2);
  ASSERT_EQ(first.outputs_size(), spec.output_priors_size());
  EXPECT_EQ(first.inputs_size(), 0);
  for (int k = 0; k < first.outputs_size(); ++k) {
    EXPECT_EQ(first.outputs(k).index(), static_cast<std::uint32_t>(k));
    ASSERT_EQ(first.outputs(k).prior().target_size(), 1);
    EXPECT_NE(first.outputs(k).prior().target(0), second.outputs(k).prior().target(0));
    // Everything but the target is the spec's own prior.
    v1::ComponentPrior rest = first.outputs(k).prior();
    rest.clear_target();
    v1::ComponentPrior expected = spec.output_priors(k);
    expected.clear_target();
    EXPECT_EQ(rest.SerializeAsString(), expected.SerializeAsString());
  }
  // The server takes the update: the same state with moved references gets another plan.
  absl::StatusOr<v1::CreateSessionResponse> a = client_->CreateSession(spec), b = client_->CreateSession(spec);
  ASSERT_TRUE(a.ok() && b.ok());
  v1::Step plain;
  plain.mutable_state()->Add(workload_.states[0].begin(), workload_.states[0].end());
  v1::Step moved = plain;
  *moved.mutable_update() = loadtest::MovingReferences(spec, 40);
  absl::StatusOr<v1::SolveResult> without = client_->Solve(a->session_id(), plain);
  absl::StatusOr<v1::SolveResult> with = client_->Solve(b->session_id(), moved);
  ASSERT_TRUE(without.ok() && with.ok()) << without.status() << with.status();
  ASSERT_TRUE(without->has_plan() && with->has_plan());
  EXPECT_NE(without->objective(), with->objective());
  // And a closed-loop level with them runs without errors.
  loadtest::LevelConfig config = ShortLevel(2);
  absl::StatusOr<loadtest::LevelReport> r = loadtest::RunLevel(
      target_, {&workload_.spec, &workload_.states, /*closed_loop=*/true, /*new_references=*/true}, config);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->tally.errors.empty());
  EXPECT_GT(r->tally.latency_ms.size(), 0u);
}

TEST_F(LoadTest, TransportFloorIsMeasuredOnTheServersHealthService) {
  absl::StatusOr<loadtest::TransportFloor> floor = loadtest::MeasureTransportFloor(target_, 50);
  ASSERT_TRUE(floor.ok()) << floor.status();
  EXPECT_EQ(floor->calls, 50);
  EXPECT_GT(floor->p50_us, 0.0);
  EXPECT_LE(floor->p50_us, floor->p99_us);
  // No comparison with a Control step's round trip: a health check is a unary call (a new
  // HTTP/2 stream each time) and a step is one message on an open stream, so either can be
  // the faster on a loaded machine, and two timings taken at different moments of a shared
  // machine say nothing about the mechanism.
  // Nothing is listening here: a clear error, no hang.
  absl::StatusOr<loadtest::TransportFloor> none = loadtest::MeasureTransportFloor("127.0.0.1:1", 1);
  EXPECT_EQ(none.status().code(), absl::StatusCode::kUnavailable);
}

TEST_F(LoadTest, EchoServerAnswersEveryStepWithItsFixedPlanInBothModes) {
  v1::SolveResult plan;
  plan.set_status(v1::SOLVE_STATUS_CONVERGED);
  plan.set_iterations(7);
  for (int i = 0; i < 90; ++i) plan.add_inputs(0.01 * i);
  absl::StatusOr<std::unique_ptr<loadtest::EchoControlServer>> echo = loadtest::EchoControlServer::Start(plan);
  ASSERT_TRUE(echo.ok()) << echo.status();
  loadtest::LevelConfig config = ShortLevel(3);
  absl::StatusOr<loadtest::LevelReport> closed = loadtest::RunLevel((*echo)->target(), Plan(true), config);
  ASSERT_TRUE(closed.ok()) << closed.status();
  EXPECT_TRUE(closed->tally.errors.empty());
  EXPECT_GT(closed->tally.latency_ms.size(), 30u);
  EXPECT_EQ(closed->tally.sent, closed->tally.latency_ms.size());
  // The load generator reads the echoed plan as it reads the server's.
  EXPECT_EQ(closed->tally.iterations, 7u * closed->tally.latency_ms.size());
  config.closed_loop = false;
  config.rate_per_s = 600.0;
  absl::StatusOr<loadtest::LevelReport> open = loadtest::RunLevel((*echo)->target(), Plan(false), config);
  ASSERT_TRUE(open.ok()) << open.status();
  EXPECT_TRUE(open->tally.errors.empty());
  EXPECT_EQ(open->tally.superseded, 0u);  // it never queues, so nothing is ever superseded
  EXPECT_EQ(open->tally.sent, open->tally.latency_ms.size());
  EXPECT_GT(open->tally.sent, 60u);
}

TEST_F(LoadTest, EchoAndBarePeersRunAsChildProcesses) {
  // nupmpc-loadtest-peer, as nupmpc-loadtest starts it: the echo answers with this server's
  // plan, then the child exits when the parent lets go of it.
  const std::string instance = std::string(NUPMPC_BENCHMARK_DIR) + "/masses_N30.json";
  absl::StatusOr<std::unique_ptr<loadtest::EchoProcess>> echo = loadtest::EchoProcess::Spawn(
      {NUPMPC_LOADTEST_PEER_BINARY, "--server=" + target_, "--instance=" + instance, "--echo_busy_us=200"});
  ASSERT_TRUE(echo.ok()) << echo.status();
  EXPECT_NE((*echo)->target(), target_);
  absl::StatusOr<loadtest::LevelReport> r = loadtest::RunLevel((*echo)->target(), Plan(true), ShortLevel(1));
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->tally.errors.empty());
  EXPECT_GT(r->tally.latency_ms.size(), 10u);
  // Busy 200 µs per step before it answers, and its answer is the server's real plan.
  EXPECT_GE(r->p50_ms, 0.2);
  EXPECT_GT(r->tally.iterations, 0u);
  echo->reset();  // returns once the child has exited

  // The bare peer: it solves, so its answers carry the solver's iterations.
  absl::StatusOr<std::unique_ptr<loadtest::EchoProcess>> bare =
      loadtest::EchoProcess::Spawn({NUPMPC_LOADTEST_PEER_BINARY, "--bare"});
  ASSERT_TRUE(bare.ok()) << bare.status();
  absl::StatusOr<loadtest::LevelReport> solved = loadtest::RunLevel((*bare)->target(), Plan(true), ShortLevel(2));
  ASSERT_TRUE(solved.ok()) << solved.status();
  EXPECT_TRUE(solved->tally.errors.empty());
  EXPECT_GT(solved->tally.latency_ms.size(), 10u);
  EXPECT_EQ(solved->tally.no_plan, 0u);
  EXPECT_GT(solved->tally.iterations, 0u);
  bare->reset();

  // A child that never names a target is an error, not a hang.
  absl::StatusOr<std::unique_ptr<loadtest::EchoProcess>> mute = loadtest::EchoProcess::Spawn({"/bin/true"});
  EXPECT_EQ(mute.status().code(), absl::StatusCode::kUnavailable);
}

// Every closed-loop state of `w` through one Control stream on `stub`, a session created
// from w.spec; the answers in order (the first message's answer left out).
std::vector<v1::ControlResponse> StepThrough(v1::MpcService::Stub& stub, const Workload& w, int rounds) {
  grpc::ClientContext context;
  auto stream = stub.Control(&context);
  v1::ControlRequest first;
  *first.mutable_spec() = w.spec;
  std::vector<v1::ControlResponse> answers;
  v1::ControlResponse response;
  if (!stream->Write(first) || !stream->Read(&response)) return answers;
  std::uint64_t sequence = 0;
  for (int r = 0; r < rounds; ++r) {
    for (std::size_t t = 0; t < w.states.size(); ++t) {
      v1::ControlRequest step;
      step.set_sequence(++sequence);
      step.mutable_step()->mutable_state()->Add(w.states[t].begin(), w.states[t].end());
      if (t == 0 && r > 0) step.mutable_step()->set_warm_start(v1::WARM_START_COLD);
      if (!stream->Write(step) || !stream->Read(&response)) return answers;
      answers.push_back(response);
    }
  }
  stream->WritesDone();
  (void)stream->Finish();
  return answers;
}

TEST_F(LoadTest, BarePeerSolvesEveryStepAsTheServerDoes) {
  absl::StatusOr<std::unique_ptr<loadtest::EchoControlServer>> bare = loadtest::EchoControlServer::StartSolving();
  ASSERT_TRUE(bare.ok()) << bare.status();
  const auto bare_stub = v1::MpcService::NewStub(nupmpc::OpenChannel((*bare)->target()));
  const std::vector<v1::ControlResponse> from_server = StepThrough(client_->stub(), workload_, 2);
  const std::vector<v1::ControlResponse> from_bare = StepThrough(*bare_stub, workload_, 2);
  ASSERT_EQ(from_server.size(), 2 * workload_.states.size());
  ASSERT_EQ(from_bare.size(), from_server.size());
  for (std::size_t i = 0; i < from_server.size(); ++i) {
    ASSERT_TRUE(from_bare[i].result().has_plan()) << i << ": " << from_bare[i].error_message();
    EXPECT_EQ(from_bare[i].sequence(), from_server[i].sequence());
    // The same steps, the same warm starts: the same plans, bit for bit.
    EXPECT_THAT(from_bare[i].result().inputs(), ::testing::ElementsAreArray(from_server[i].result().inputs())) << i;
    EXPECT_EQ(from_bare[i].result().iterations(), from_server[i].result().iterations()) << i;
  }

  // A step before any spec is answered with an error; a state of the wrong size with the
  // server's own error for it.
  grpc::ClientContext context;
  auto stream = bare_stub->Control(&context);
  v1::ControlRequest orphan;
  orphan.set_sequence(1);
  orphan.mutable_step()->add_state(1.0);
  v1::ControlResponse response;
  ASSERT_TRUE(stream->Write(orphan) && stream->Read(&response));
  EXPECT_NE(response.error_code(), 0);
  EXPECT_THAT(response.error_message(), ::testing::HasSubstr("spec"));
  v1::ControlRequest short_state;
  *short_state.mutable_spec() = workload_.spec;
  short_state.set_sequence(2);
  short_state.mutable_step()->add_state(1.0);
  ASSERT_TRUE(stream->Write(short_state) && stream->Read(&response));
  EXPECT_EQ(response.session_id(), "bare");
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  absl::StatusOr<v1::CreateSessionResponse> session = client_->CreateSession(workload_.spec);
  ASSERT_TRUE(session.ok()) << session.status();
  absl::StatusOr<v1::SolveResult> refused = client_->Solve(session->session_id(), short_state.step());
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(response.error_code(), static_cast<int>(refused.status().code())) << response.error_message();
  EXPECT_EQ(response.error_message(), refused.status().message());
}

TEST_F(LoadTest, OpenLoopArrivalsAreAnsweredOrSupersededNeverLost) {
  const Workload w = MassesWorkload();
  loadtest::LevelConfig config;
  config.concurrency = 2;
  config.closed_loop = false;
  config.rate_per_s = 400.0;
  config.duration_s = 0.8;
  config.warmup_s = 0.1;
  absl::StatusOr<loadtest::LevelReport> r =
      loadtest::RunLevel(target_, {&w.spec, &w.states, /*closed_loop=*/false}, config);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->tally.errors.empty());
  EXPECT_EQ(r->tally.sent, r->tally.latency_ms.size() + r->tally.superseded);
  // Poisson arrivals at 400/s for 0.8 s: 320 expected; 5 standard deviations either way.
  EXPECT_NEAR(static_cast<double>(r->tally.sent), 320.0, 5.0 * std::sqrt(320.0));
}

TEST_F(LoadTest, MoreStreamsThanTheQueueHoldsGetResourceExhausted) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.worker_threads = 1;
  options.queue_capacity = 1;
  StartServer(options);
  const Workload w = MassesWorkload();
  loadtest::LevelConfig config;
  config.concurrency = 12;
  config.closed_loop = false;
  config.rate_per_s = 20000.0;  // far beyond one worker
  config.duration_s = 0.5;
  config.warmup_s = 0.0;
  absl::StatusOr<loadtest::LevelReport> r =
      loadtest::RunLevel(target_, {&w.spec, &w.states, /*closed_loop=*/false}, config);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_GT(r->tally.errors["RESOURCE_EXHAUSTED"], 0u);
  EXPECT_GT(r->tally.latency_ms.size(), 0u);  // and the admitted ones were solved
  EXPECT_EQ(r->tally.errors.size(), 1u);      // nothing else went wrong
}

TEST_F(LoadTest, IdleSessionsGrowTheServersMemoryAndGiveItBack) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.session_compact_idle_s = 0.5;
  StartServer(options);
  const Workload w = MassesWorkload();
  absl::StatusOr<loadtest::IdleSessionsReport> r = loadtest::RunIdleSessions(target_, w.spec, 200, false);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_GT(r->rss_before, 0u);
  // 200 sessions of ~200 KiB each: tens of MiB, far above allocator noise.
  EXPECT_GT(r->rss_with_sessions, r->rss_before + 200u * 100u * 1024u);
  // Compacted idle sessions give their solver scratch (a quarter of a session) back.
  EXPECT_LT(r->rss_idle, r->rss_with_sessions - 200u * 25u * 1024u);
  EXPECT_LT(r->rss_after, r->rss_idle - 200u * 50u * 1024u);
  EXPECT_EQ(client_->ListSessions()->size(), 0u);
}

TEST(CoreBaseline, MeasuresEveryStepOfEveryRound) {
  const Workload w = MassesWorkload();
  absl::StatusOr<loadtest::CoreBaseline> b = loadtest::MeasureCoreBaseline(w.spec, w.states, 2);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->solves, static_cast<int>(2 * w.states.size()));
  EXPECT_GT(b->median_ms, 0.0);
  EXPECT_LE(b->median_ms, b->p99_ms);
  EXPECT_GT(b->mean_iterations, 1.0);
  EXPECT_GT(b->mean_ms, 0.0);
  // The inline peer replays these, one per closed-loop state in order.
  ASSERT_EQ(b->state_ms.size(), w.states.size());
  for (double ms : b->state_ms) EXPECT_GT(ms, 0.0);
  // The same steps with the moving references a --new_references stream sends: accepted by
  // the server's conversion and applied, as the server applies them.
  absl::StatusOr<loadtest::CoreBaseline> tracking =
      loadtest::MeasureCoreBaseline(w.spec, w.states, 2, /*new_references=*/true);
  ASSERT_TRUE(tracking.ok()) << tracking.status();
  EXPECT_EQ(tracking->solves, b->solves);
}

TEST(CoreBaseline, SessionsInTurnEachTakeEveryStep) {
  const Workload w = MassesWorkload();
  absl::StatusOr<loadtest::CoreBaseline> b =
      loadtest::MeasureCoreBaseline(w.spec, w.states, 1, /*new_references=*/false, /*sessions=*/3);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->solves, static_cast<int>(3 * w.states.size()));
  // Every session goes through the same states with the same warm starts: the same
  // iterations per step as one session alone.
  absl::StatusOr<loadtest::CoreBaseline> one = loadtest::MeasureCoreBaseline(w.spec, w.states, 1);
  ASSERT_TRUE(one.ok()) << one.status();
  EXPECT_DOUBLE_EQ(b->mean_iterations, one->mean_iterations);
  ASSERT_EQ(b->state_ms.size(), w.states.size());
  for (double ms : b->state_ms) EXPECT_GT(ms, 0.0);
}

TEST(LevelRounds, MergedRoundsCountEveryAnswerOverTheirSummedTime) {
  const auto round = [](std::vector<double> latency_ms, double measured_s, double least, double most) {
    loadtest::LevelReport r;
    r.config.concurrency = 2;
    r.config.duration_s = measured_s;
    r.measured_s = measured_s;
    r.tally.latency_ms = latency_ms;
    r.tally.service_ms = latency_ms;
    r.tally.solve_ms = std::vector<double>(latency_ms.size(), 0.1);
    r.tally.iterations = 2 * latency_ms.size();
    r.tally.sent = latency_ms.size();
    r.tally.errors["UNAVAILABLE"] = 1;
    r.stream_min_share = least;
    r.stream_max_share = most;
    loadtest::Summarize(r);
    return r;
  };
  const loadtest::LevelReport merged =
      loadtest::MergeRounds({round({1, 2, 3}, 1.0, 0.9, 1.1), round({4, 5, 6, 7, 8, 9, 10}, 1.5, 0.8, 1.05)});
  EXPECT_EQ(merged.tally.latency_ms.size(), 10u);
  EXPECT_DOUBLE_EQ(merged.measured_s, 2.5);
  EXPECT_DOUBLE_EQ(merged.config.duration_s, 2.5);
  EXPECT_DOUBLE_EQ(merged.solves_per_s, 4.0);
  EXPECT_EQ(merged.p50_ms, 5.0);  // over all answers, not a mean of the rounds' medians
  EXPECT_EQ(merged.max_ms, 10.0);
  EXPECT_DOUBLE_EQ(merged.mean_iterations, 2.0);
  EXPECT_EQ(merged.tally.errors.at("UNAVAILABLE"), 2u);
  EXPECT_DOUBLE_EQ(merged.stream_min_share, 0.8);
  EXPECT_DOUBLE_EQ(merged.stream_max_share, 1.1);
}

TEST(FleetRounds, MergedOverEveryCallAndEverySolvedStep) {
  const auto round = [](std::vector<double> call_ms, double measured_s, std::uint64_t solved,
                        std::uint64_t iterations) {
    loadtest::FleetReport r;
    r.sessions = 4;
    r.calls = call_ms.size();
    r.call_ms = std::move(call_ms);
    r.measured_s = measured_s;
    r.answered = 4 * r.calls;
    r.solved = solved;
    r.iterations = iterations;
    r.mean_iterations = static_cast<double>(iterations) / static_cast<double>(solved);
    r.step_errors = 1;
    return r;
  };
  const loadtest::FleetReport merged =
      loadtest::MergeFleetRounds({round({1, 2, 3}, 1.0, 12, 24), round({4, 5, 6, 7, 8, 9, 10}, 1.5, 28, 28)});
  EXPECT_EQ(merged.sessions, 4);
  EXPECT_EQ(merged.calls, 10u);
  EXPECT_EQ(merged.answered, 40u);
  EXPECT_DOUBLE_EQ(merged.measured_s, 2.5);
  EXPECT_DOUBLE_EQ(merged.steps_per_s, 16.0);
  EXPECT_EQ(merged.iterations, 52u);
  EXPECT_DOUBLE_EQ(merged.mean_iterations, 52.0 / 40);  // not the mean of the rounds' means (1.5)
  EXPECT_EQ(merged.call_p50_ms, 5.0);                   // over all calls, not a mean of the rounds' medians
  EXPECT_EQ(merged.call_p99_ms, 10.0);
  EXPECT_EQ(merged.step_errors, 2u);
}

TEST_F(LoadTest, AFleetLevelCountsEveryStepOfEveryCall) {
  absl::StatusOr<loadtest::FleetReport> r = loadtest::RunFleetLevel(target_, {}, Plan(true), 3, 1, 0.5, 0.05);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_GT(r->calls, 0u);
  EXPECT_EQ(r->call_ms.size(), r->calls);
  EXPECT_EQ(r->answered, 3 * r->calls);
  EXPECT_EQ(r->solved, r->answered);  // one call at a time: nothing superseded
  EXPECT_EQ(r->step_errors, 0u);
  EXPECT_GE(r->iterations, r->solved);  // every solve takes a pass at least
  EXPECT_GT(r->measured_s, 0.0);
}

TEST_F(LoadTest, AFleetInTwoCallsInFlightStepsEachSessionInOneOfThem) {
  // 3 sessions in 2 callers: calls of 1 and of 2 sessions, each session in one caller's calls only.
  absl::StatusOr<loadtest::FleetReport> r = loadtest::RunFleetLevel(target_, {}, Plan(true), 3, 2, 1.0, 0.05);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->calls_in_flight, 2);
  ASSERT_GE(r->calls, 2u);
  EXPECT_EQ(r->call_ms.size(), r->calls);
  // Calls of 1 and of 2 steps were both counted: more answers than calls, fewer than 2 each.
  EXPECT_GT(r->answered, r->calls);
  EXPECT_LT(r->answered, 2 * r->calls);
  EXPECT_EQ(r->solved, r->answered);  // no session in two calls at once: nothing superseded
  EXPECT_EQ(r->step_errors, 0u);
  // The callers' common window of about 1 s, not their sum (about 2 s).
  EXPECT_GT(r->measured_s, 0.5);
  EXPECT_LT(r->measured_s, 1.6);
  EXPECT_DOUBLE_EQ(r->steps_per_s, static_cast<double>(r->answered) / r->measured_s);
  for (const int refused : {0, 4}) {
    const absl::StatusOr<loadtest::FleetReport> bad =
        loadtest::RunFleetLevel(target_, {}, Plan(true), 3, refused, 0.1, 0);
    EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument) << refused;
  }
}

TEST(CoreBaseline, SteppingAFleetInTurnTimesTheWarmPeriodsAndRefusesAWrongState) {
  const Workload w = MassesWorkload();
  absl::StatusOr<loadtest::FleetCoreBaseline> warm = loadtest::MeasureFleetCore(w.spec, w.states, 3, 2);
  ASSERT_TRUE(warm.ok()) << warm.status();
  EXPECT_GT(warm->mean_ms, 0.0);
  EXPECT_TRUE(std::isfinite(warm->mean_ms));
  // The cold period is left out. One session, one timed period p: the timed step is
  // states[p] warm-started from states[p - 1]'s cold solve, whose iterations the stream
  // baseline gives: {states[p - 1]} alone is the cold step, {states[p - 1], states[p]} both.
  for (const int p : {1, 5}) {
    absl::StatusOr<loadtest::FleetCoreBaseline> one = loadtest::MeasureFleetCore(w.spec, w.states, 1, 1, p);
    absl::StatusOr<loadtest::CoreBaseline> cold = loadtest::MeasureCoreBaseline(w.spec, {w.states[p - 1]}, 1);
    absl::StatusOr<loadtest::CoreBaseline> both =
        loadtest::MeasureCoreBaseline(w.spec, {w.states[p - 1], w.states[p]}, 1);
    ASSERT_TRUE(one.ok() && cold.ok() && both.ok());
    const double warm_step_iterations = 2.0 * both->mean_iterations - cold->mean_iterations;
    ASSERT_NE(warm_step_iterations, cold->mean_iterations) << "the instance must tell a cold step from a warm one";
    EXPECT_DOUBLE_EQ(one->mean_iterations, warm_step_iterations) << "first timed period " << p;
  }
  EXPECT_FALSE(loadtest::MeasureFleetCore(w.spec, w.states, 1, 1, 0).ok());
  const std::vector<std::vector<double>> wrong = {std::vector<double>(w.states[0].size() + 1, 0.0)};
  EXPECT_FALSE(loadtest::MeasureFleetCore(w.spec, wrong, 3, 1).ok());
  EXPECT_FALSE(loadtest::MeasureFleetCore(w.spec, w.states, 3, 0).ok());
}

TEST(UsableCores, TheServersCoresAtMostTheCpusItMayRunOn) {
  EXPECT_EQ(loadtest::UsableCores(2, "0"), 1);    // --threads 1 pinned to one CPU: two gRPC threads share it
  EXPECT_EQ(loadtest::UsableCores(2, "0-3"), 2);  // more CPUs than solver cores
  EXPECT_EQ(loadtest::UsableCores(4, "0,2-3"), 3);
  EXPECT_EQ(loadtest::UsableCores(2, ""), 2);   // a server that does not report its CPUs
  EXPECT_EQ(loadtest::UsableCores(2, "x"), 2);  // nor readably
}

TEST(StarvedAStream, AClosedLoopStreamOutsideAFactorTwoOfTheMean) {
  const auto level = [](bool closed_loop, int concurrency, double least, double most, int answers_per_stream = 100) {
    loadtest::LevelReport l;
    l.config.closed_loop = closed_loop;
    l.config.concurrency = concurrency;
    l.stream_min_share = least;
    l.stream_max_share = most;
    l.tally.latency_ms.assign(static_cast<std::size_t>(concurrency * answers_per_stream), 0.1);
    return l;
  };
  EXPECT_FALSE(loadtest::StarvedAStream(level(true, 64, 0.98, 1.02)));
  EXPECT_FALSE(loadtest::StarvedAStream(level(true, 64, 0.5, 2.0)));    // the bound itself is fair
  EXPECT_TRUE(loadtest::StarvedAStream(level(true, 64, 0.49, 1.01)));   // one stream under half the mean
  EXPECT_TRUE(loadtest::StarvedAStream(level(true, 64, 0.0, 1.03)));    // one never answered
  EXPECT_TRUE(loadtest::StarvedAStream(level(true, 8, 0.86, 2.01)));    // one served over twice the mean
  EXPECT_TRUE(loadtest::StarvedAStream(level(true, 8, 0.0, 2.5)));      // one stream took most
  EXPECT_FALSE(loadtest::StarvedAStream(level(true, 8, 0.4, 1.6, 5)));  // 5 answers a stream: noise
  EXPECT_FALSE(loadtest::StarvedAStream(level(false, 64, 0.0, 3.0)));   // open loop: arrivals decide
  EXPECT_FALSE(loadtest::StarvedAStream(level(true, 1, 1.0, 1.0)));
}

TEST(Quantile, NearestRank) {
  std::vector<double> v = {5, 1, 4, 2, 3};
  EXPECT_EQ(loadtest::Quantile(v, 0.5), 3);
  EXPECT_EQ(loadtest::Quantile(v, 0.99), 5);
  EXPECT_EQ(loadtest::Quantile(v, 0.0), 1);
  std::vector<double> empty;
  EXPECT_EQ(loadtest::Quantile(empty, 0.5), 0.0);
}

TEST(SessionCompaction, ACompactedSessionContinuesBitIdentically) {
  const Workload w = MassesWorkload();
  server::WorkerPool pool(/*threads=*/1, /*queue_capacity=*/4, /*max_queue_wait_ms=*/0.0);
  server::SessionRegistry kept_registry(4, pool), compacted_registry(4, pool);
  std::shared_ptr<server::SessionEntry> kept, compacted;
  for (auto [registry, entry] : {std::pair{&kept_registry, &kept}, std::pair{&compacted_registry, &compacted}}) {
    absl::StatusOr<server::BuiltSession> built = server::BuildSession(w.spec, {});
    ASSERT_TRUE(built.ok()) << built.status();
    absl::StatusOr<std::shared_ptr<server::SessionEntry>> added =
        registry->Add(std::move(built->solver), server::SessionTiming{}, /*owned_by_stream=*/false);
    ASSERT_TRUE(added.ok());
    *entry = *added;
  }
  for (std::size_t t = 0; t < 6; ++t) {
    v1::Step step;
    step.mutable_state()->Add(w.states[t].begin(), w.states[t].end());
    v1::SolveResult a, b;
    ASSERT_TRUE(server::SolveStep(*kept, step, {}, &a).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_EQ(compacted_registry.CompactIdle(0.001), 1) << "step " << t;
    EXPECT_TRUE(compacted->compacted);
    ASSERT_TRUE(server::SolveStep(*compacted, step, {}, &b).ok());
    EXPECT_FALSE(compacted->compacted);
    EXPECT_EQ(a.iterations(), b.iterations()) << "step " << t;
    EXPECT_EQ(a.warm_started(), b.warm_started()) << "step " << t;
    ASSERT_EQ(a.inputs_size(), b.inputs_size());
    for (int i = 0; i < a.inputs_size(); ++i) ASSERT_EQ(a.inputs(i), b.inputs(i)) << "step " << t << " input " << i;
  }
}

}  // namespace
}  // namespace nupmpc::testing
