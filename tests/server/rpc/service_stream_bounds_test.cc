// Control streams are bounded (a client that does not read its answers makes the server
// stop reading, not queue without end; the number of open streams has a limit), and a
// result never carries a plan computed for another state than its step's.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <thread>
#include <vector>

#include "client/channel_factory.h"
#include "gmock/gmock.h"
#include "server/metrics_exposition.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;
using Stream = grpc::ClientReaderWriter<v1::ControlRequest, v1::ControlResponse>;

// A double integrator, x = [position, velocity], one bounded input, N = 20.
v1::ProblemSpec DoubleIntegrator() {
  v1::ProblemSpec spec;
  v1::Model* m = spec.mutable_model();
  m->set_num_states(2);
  m->set_num_inputs(1);
  m->set_num_outputs(1);
  m->set_horizon(20);
  v1::Matrix* a = m->add_a();
  a->set_rows(2);
  a->set_cols(2);
  for (double v : {1.0, 0.1, 0.0, 1.0}) a->add_data(v);
  v1::Matrix* b = m->add_b();
  b->set_rows(2);
  b->set_cols(1);
  for (double v : {0.005, 0.1}) b->add_data(v);
  v1::Matrix* c = m->add_c();
  c->set_rows(1);
  c->set_cols(2);
  for (double v : {1.0, 0.0}) c->add_data(v);
  for (int i = 0; i < 2; ++i) spec.mutable_initial_state()->add_mean(0.0);
  v1::ComponentPrior* u = spec.add_input_priors();
  u->set_kind(v1::PRIOR_KIND_BOX);
  u->add_weight(0.1);
  u->add_lower(-1.0);
  u->add_upper(1.0);
  v1::ComponentPrior* y = spec.add_output_priors();
  y->add_weight(1.0);
  y->add_target(0.0);
  return spec;
}

v1::ControlRequest StepRequest(std::uint64_t sequence, double position) {
  v1::ControlRequest r;
  r.set_sequence(sequence);
  r.mutable_step()->add_state(position);
  r.mutable_step()->add_state(0.0);
  return r;
}

class ServiceStreamBoundsTest : public ServiceTest {};

TEST_F(ServiceStreamBoundsTest, AClientThatDoesNotReadMakesTheStreamStopReadingAndEveryStepIsAnsweredOnce) {
  // A client that does not read takes at most its flow-control window of answers. Without
  // BDP probing that window stays at gRPC's initial size, far below the answers to the
  // steps below; with it, a fast server can grow it until it holds them all, and the
  // server's writes never wait (so it never has a reason to stop reading).
  ChannelOptions no_window_growth;
  no_window_growth.extra.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  const std::shared_ptr<grpc::Channel> channel = OpenChannel(target_, no_window_growth);
  const std::unique_ptr<v1::MpcService::Stub> stub = v1::MpcService::NewStub(channel);
  grpc::ClientContext context;
  std::unique_ptr<Stream> stream = stub->Control(&context);
  v1::ControlRequest first = StepRequest(0, 1.0);
  *first.mutable_spec() = DoubleIntegrator();
  ASSERT_TRUE(stream->Write(first));
  // Many small steps, none of the answers read: the writer blocks once the server stops
  // reading and HTTP/2 flow control holds the rest, so it runs on its own thread.
  constexpr std::uint64_t kSteps = 20000;
  std::thread writer([&] {
    for (std::uint64_t i = 1; i <= kSteps; ++i) {
      if (!stream->Write(StepRequest(i, 1.0 + 1e-6 * static_cast<double>(i)))) return;
    }
    stream->WritesDone();
  });
  // Until the server has stopped reading (it says so in GetServerInfo).
  std::uint64_t pauses = 0;
  for (int i = 0; i < 200 && pauses == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    auto info = client_->GetServerInfo();
    ASSERT_TRUE(info.ok());
    pauses = info->control_stream_read_pauses();
  }
  EXPECT_GE(pauses, 1u) << "the stream never stopped reading";
  // Now read everything: one answer per message (a superseded step's answer may overtake
  // the one being solved), and the newest step gets a plan.
  v1::ControlResponse response;
  std::vector<int> answers_per_step(kSteps + 1, 0);
  v1::ControlResponse newest;
  while (stream->Read(&response)) {
    ASSERT_LE(response.sequence(), kSteps);
    ++answers_per_step[response.sequence()];
    if (response.sequence() == kSteps) newest = response;
  }
  writer.join();
  EXPECT_TRUE(stream->Finish().ok());
  EXPECT_EQ(std::count(answers_per_step.begin(), answers_per_step.end(), 1), static_cast<long>(kSteps + 1));
  EXPECT_EQ(newest.result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_TRUE(newest.result().has_plan());
}

TEST_F(ServiceStreamBoundsTest, OpenControlStreamsHaveAServerWideLimit) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.max_control_streams = 2;
  StartServer(options);
  auto open = [&](grpc::ClientContext* context) {
    std::unique_ptr<Stream> stream = client_->stub().Control(context);
    v1::ControlRequest first = StepRequest(0, 1.0);
    *first.mutable_spec() = DoubleIntegrator();
    stream->Write(first);
    return stream;
  };
  grpc::ClientContext c1, c2, c3, c4;
  auto s1 = open(&c1), s2 = open(&c2);
  v1::ControlResponse r;
  ASSERT_TRUE(s1->Read(&r));
  ASSERT_TRUE(s2->Read(&r));
  auto s3 = open(&c3);
  EXPECT_FALSE(s3->Read(&r));
  const grpc::Status refused = s3->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(refused.error_message(), HasSubstr("max_control_streams"));
  s1->WritesDone();
  EXPECT_TRUE(s1->Finish().ok());
  // The closed stream's place is free again (its OnDone may lag the client's Finish).
  bool served = false;
  for (int attempt = 0; attempt < 50 && !served; ++attempt) {
    grpc::ClientContext context;
    auto s = open(&context);
    served = s->Read(&r);
    s->WritesDone();
    (void)s->Finish();
    if (!served) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(served);
  s2->WritesDone();
  EXPECT_TRUE(s2->Finish().ok());
}

TEST_F(ServiceStreamBoundsTest, AStreamThatNeverSendsItsFirstMessageIsEndedAndGivesItsPlaceBack) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.max_control_streams = 1;
  options.first_message_timeout_s = 1.0;
  StartServer(options);
  // A silent stream takes the only place: without the timeout it would hold it for ever.
  grpc::ClientContext silent_context;
  // Without the server's timeout the client's own deadline ends it (another message).
  silent_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  std::unique_ptr<Stream> silent = client_->stub().Control(&silent_context);
  v1::ControlResponse r;
  const auto opened = std::chrono::steady_clock::now();
  EXPECT_FALSE(silent->Read(&r));
  const grpc::Status ended = silent->Finish();
  EXPECT_GE(std::chrono::steady_clock::now() - opened, std::chrono::milliseconds(900));
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_THAT(ended.error_message(), HasSubstr("first_message_timeout_s"));
  // Its place is free again (OnDone may lag the client's Finish), and a stream that sent
  // its attach at once stays open well past the timeout.
  ReconnectOptions no_reconnect;
  no_reconnect.budget = std::chrono::milliseconds(0);
  absl::StatusOr<std::unique_ptr<Session>> session = absl::UnavailableError("not opened");
  for (int attempt = 0; attempt < 100 && !session.ok(); ++attempt) {
    session = client_->OpenSession(DoubleIntegrator(), no_reconnect);
    if (!session.ok()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(session.ok()) << session.status();
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  v1::Step step;
  step.add_state(1.0);
  step.add_state(0.0);
  absl::StatusOr<v1::SolveResult> result = (*session)->Step(step);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(result->has_plan());
  EXPECT_EQ((*session)->reconnects(), 0);
  absl::StatusOr<v1::GetServerInfoResponse> info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->limits().first_message_timeout_s(), 1.0);
  EXPECT_EQ(info->errors_by_code().at("DEADLINE_EXCEEDED"), 1u);
}

// Why streams ended is counted by cause (nupmpc_control_stream_ends_total), and the held
// periods clients report with their steps are added up (nupmpc_client_held_periods_total).
TEST_F(ServiceStreamBoundsTest, StreamEndsAreCountedByCauseAndReportedHeldPeriodsAddUp) {
  server::ServerState& state = server_->state();
  const auto ends = [&](server::StreamEnd cause) { return state.stream_ends.count(cause); };
  const auto wait_for_ends = [&](server::StreamEnd cause, std::uint64_t n) {
    for (int i = 0; i < 200 && ends(cause) < n; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return ends(cause);
  };
  const auto attached = [&](grpc::ClientContext* context) {
    std::unique_ptr<Stream> stream = client_->stub().Control(context);
    v1::ControlRequest hello;
    *hello.mutable_spec() = DoubleIntegrator();
    hello.set_sequence(1);
    v1::ControlResponse r;
    EXPECT_TRUE(stream->Write(hello) && stream->Read(&r));
    return stream;
  };
  {  // A half-close after two steps, the second one saying 3 periods went unanswered.
    grpc::ClientContext context;
    std::unique_ptr<Stream> stream = attached(&context);
    v1::ControlResponse r;
    v1::ControlRequest step = StepRequest(2, 1.0);
    ASSERT_TRUE(stream->Write(step) && stream->Read(&r));
    step = StepRequest(3, 0.5);
    step.set_held_periods(3);
    ASSERT_TRUE(stream->Write(step) && stream->Read(&r));
    stream->WritesDone();
    EXPECT_TRUE(stream->Finish().ok());
  }
  EXPECT_EQ(wait_for_ends(server::StreamEnd::kClientClosed, 1), 1u);
  EXPECT_EQ(state.client_held_periods.load(), 3u);
  {  // A cancellation right after a step: the client's own.
    grpc::ClientContext context;
    std::unique_ptr<Stream> stream = attached(&context);
    v1::ControlResponse r;
    ASSERT_TRUE(stream->Write(StepRequest(2, 1.0)) && stream->Read(&r));
    context.TryCancel();
    (void)stream->Finish();
  }
  EXPECT_EQ(wait_for_ends(server::StreamEnd::kClientGone, 1), 1u);
  {  // A first message the server refuses.
    grpc::ClientContext context;
    std::unique_ptr<Stream> stream = client_->stub().Control(&context);
    v1::ControlRequest hello;
    hello.set_session_id("no-such-session");
    v1::ControlResponse r;
    ASSERT_TRUE(stream->Write(hello));
    EXPECT_FALSE(stream->Read(&r));
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);  // not an id
  }
  EXPECT_EQ(wait_for_ends(server::StreamEnd::kServerEnded, 1), 1u);
  EXPECT_EQ(ends(server::StreamEnd::kKeepalive), 0u);  // found by real keepalive: tests/soak/faults.py
  const std::string metrics = server::RenderPrometheusMetrics(state);
  EXPECT_THAT(metrics, HasSubstr("nupmpc_control_stream_ends_total{cause=\"client_closed\"} 1\n"));
  EXPECT_THAT(metrics, HasSubstr("nupmpc_control_stream_ends_total{cause=\"client_gone\"} 1\n"));
  EXPECT_THAT(metrics, HasSubstr("nupmpc_control_stream_ends_total{cause=\"server_ended\"} 1\n"));
  EXPECT_THAT(metrics, HasSubstr("nupmpc_client_held_periods_total 3\n"));
}

TEST_F(ServiceStreamBoundsTest, AResultWithoutAUsablePlanCarriesNoPlanAtAll) {
  grpc::ClientContext context;
  std::unique_ptr<Stream> stream = client_->stub().Control(&context);
  v1::ControlRequest first = StepRequest(0, 1e15);
  *first.mutable_spec() = DoubleIntegrator();
  ASSERT_TRUE(stream->Write(first));
  v1::ControlResponse r;
  ASSERT_TRUE(stream->Read(&r));
  ASSERT_EQ(r.error_code(), 0) << r.error_message();
  ASSERT_TRUE(r.result().has_plan());
  EXPECT_EQ(r.result().states(0), 1e15);
  // The report's step: it broke down, and its answer carried the previous step's plan.
  ASSERT_TRUE(stream->Write(StepRequest(1, -1e300)));
  ASSERT_TRUE(stream->Read(&r));
  ASSERT_EQ(r.error_code(), 0) << r.error_message();
  const v1::SolveResult& broken = r.result();
  if (broken.has_plan()) {
    EXPECT_EQ(broken.states(0), -1e300) << "a plan, but for another state";
  } else {
    EXPECT_NE(broken.status(), v1::SOLVE_STATUS_CONVERGED);
    EXPECT_EQ(broken.inputs_size(), 0);
    EXPECT_EQ(broken.states_size(), 0);
    EXPECT_EQ(broken.outputs_size(), 0);
    EXPECT_TRUE(std::isnan(broken.objective()));
  }
  EXPECT_EQ(broken.status(), v1::SOLVE_STATUS_NUMERICAL_ERROR);
  EXPECT_FALSE(broken.has_plan());
  // The session goes on: the next state gets its own plan.
  ASSERT_TRUE(stream->Write(StepRequest(2, 0.5)));
  ASSERT_TRUE(stream->Read(&r));
  ASSERT_EQ(r.error_code(), 0) << r.error_message();
  EXPECT_TRUE(r.result().has_plan());
  EXPECT_EQ(r.result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(r.result().states(0), 0.5);
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
}

}  // namespace
}  // namespace nupmpc::testing
