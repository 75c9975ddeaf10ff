// A real nupmpc-server with --state_dir, stopped with SIGTERM under Control streams of four
// session kinds (convex, input differences, keep-out, binary inputs) and started again on
// the same port: each stream's client re-attaches by id, and the next plans are
// bit-identical, with the same pass counts, to those of a twin server that never
// restarted. Files in the state directory that fail their checks are moved aside while
// the server restores the rest, and closing a session still in the directory discards it.
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/channel_factory.h"
#include "client/problem_file.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "loadtest/instances/session_kinds.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"
#include "tests/util/loopback_port.h"
#include "tests/util/server_process.h"

namespace nupmpc::testing {
namespace {

// One Control stream, driven synchronously: one step, one answer.
class ControlStream {
 public:
  ControlStream(const std::shared_ptr<grpc::Channel>& channel, const std::string& session_id = {})
      : stub_(v1::MpcService::NewStub(channel)) {
    if (!session_id.empty()) context_.AddMetadata("x-nupmpc-session", session_id);
    context_.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    stream_ = stub_->Control(&context_);
  }
  // The first message, attach-only (its answer names the session): creates a session from
  // `spec`, or attaches to `session_id`; then the first step.
  absl::StatusOr<v1::ControlResponse> First(const v1::ProblemSpec* spec, const std::string& session_id,
                                            const std::vector<double>& state) {
    v1::ControlRequest request;
    if (spec != nullptr) *request.mutable_spec() = *spec;
    if (spec == nullptr) request.set_session_id(session_id);
    absl::StatusOr<v1::ControlResponse> hello = Exchange(request);
    if (!hello.ok()) return hello.status();
    absl::StatusOr<v1::ControlResponse> answer = Step(state);
    if (answer.ok()) answer->set_session_id(hello->session_id());
    return answer;
  }
  absl::StatusOr<v1::ControlResponse> Step(const std::vector<double>& state) {
    v1::ControlRequest request;
    request.set_sequence(++sequence_);
    request.mutable_step()->mutable_state()->Assign(state.begin(), state.end());
    return Exchange(request);
  }
  void Close() {
    stream_->WritesDone();
    (void)stream_->Finish();
  }

 private:
  absl::StatusOr<v1::ControlResponse> Exchange(const v1::ControlRequest& request) {
    v1::ControlResponse response;
    if (!stream_->Write(request) || !stream_->Read(&response)) {
      const grpc::Status status = stream_->Finish();
      return absl::UnavailableError(absl::StrCat("stream ended: ", status.error_message()));
    }
    if (response.error_code() != 0) return absl::InvalidArgumentError(response.error_message());
    return response;
  }
  std::unique_ptr<v1::MpcService::Stub> stub_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::ControlRequest, v1::ControlResponse>> stream_;
  std::uint64_t sequence_ = 0;
};

v1::ProblemSpec Masses() {
  absl::StatusOr<ProblemFile> problem = LoadProblemFile(absl::StrCat(NUPMPC_BENCHMARK_DIR, "/masses_N30.json"));
  EXPECT_TRUE(problem.ok()) << problem.status();
  return problem.ok() ? problem->spec : v1::ProblemSpec();
}

// The plant moves to the plan's predicted x[1]: the next state both servers get.
std::vector<double> NextState(const v1::SolveResult& result, int num_states) {
  return {result.states().begin() + num_states, result.states().begin() + 2 * num_states};
}

std::vector<double> InitialState(const v1::ProblemSpec& spec) {
  return {spec.initial_state().mean().begin(), spec.initial_state().mean().end()};
}

// Bit-identical plans and the same pass count.
void ExpectSamePlan(const v1::SolveResult& restarted, const v1::SolveResult& twin, const std::string& where) {
  ASSERT_TRUE(restarted.has_plan()) << where;
  ASSERT_TRUE(twin.has_plan()) << where;
  EXPECT_EQ(restarted.iterations(), twin.iterations()) << where;
  ASSERT_EQ(restarted.inputs_size(), twin.inputs_size()) << where;
  for (int i = 0; i < twin.inputs_size(); ++i) {
    ASSERT_EQ(restarted.inputs(i), twin.inputs(i)) << where << ", inputs[" << i << "]";
  }
  EXPECT_TRUE(restarted.warm_started()) << where;
}

class RestartReattachTest : public ::testing::Test {
 protected:
  void SetUp() override {
    state_dir_ = std::filesystem::path(::testing::TempDir()) / absl::StrCat("restart_reattach_test.", getpid());
    std::filesystem::remove_all(state_dir_);
  }
  void TearDown() override { std::filesystem::remove_all(state_dir_); }
  std::unique_ptr<ServerProcess> Start(int port, bool with_state_dir) {
    std::vector<std::string> flags = {"--log_level=warn", "--threads=1", "--grace_period_s=2"};
    if (with_state_dir) flags.push_back(absl::StrCat("--state_dir=", state_dir_.string()));
    auto server = std::make_unique<ServerProcess>(NUPMPC_SERVER_BINARY, port, flags);
    EXPECT_TRUE(WaitUntilServing(server->target()));
    return server;
  }
  std::filesystem::path state_dir_;
};

TEST_F(RestartReattachTest, EveryKindReattachesAfterSigtermWithTheNeverRestartedTwinsPlans) {
  const int port = FreeLoopbackPort();
  std::unique_ptr<ServerProcess> server = Start(port, /*with_state_dir=*/true);
  std::unique_ptr<ServerProcess> twin_server = Start(FreeLoopbackPort(), /*with_state_dir=*/false);
  const std::shared_ptr<grpc::Channel> twin_channel = OpenChannel(twin_server->target());
  const std::vector<bench::SessionKind> kinds = bench::SessionKindsOf(Masses());
  constexpr int kStepsBefore = 4, kStepsAfter = 3;

  std::vector<std::unique_ptr<ControlStream>> streams, twins;
  std::vector<std::string> ids;
  std::vector<std::vector<double>> states;
  {
    const std::shared_ptr<grpc::Channel> channel = OpenChannel(server->target());
    for (const bench::SessionKind& kind : kinds) {
      const int m = static_cast<int>(kind.spec.model().num_states());
      streams.push_back(std::make_unique<ControlStream>(channel));
      twins.push_back(std::make_unique<ControlStream>(twin_channel));
      std::vector<double> state = InitialState(kind.spec);
      absl::StatusOr<v1::ControlResponse> first = streams.back()->First(&kind.spec, "", state);
      absl::StatusOr<v1::ControlResponse> twin_first = twins.back()->First(&kind.spec, "", state);
      ASSERT_TRUE(first.ok() && twin_first.ok()) << kind.name << ": " << first.status() << twin_first.status();
      ids.push_back(first->session_id());
      for (int k = 1; k < kStepsBefore; ++k) {
        state = NextState(twin_first->result(), m);
        first = streams.back()->Step(state);
        twin_first = twins.back()->Step(state);
        ASSERT_TRUE(first.ok() && twin_first.ok()) << kind.name;
        ExpectSamePlan(first->result(), twin_first->result(), absl::StrCat(kind.name, " before, step ", k));
      }
      states.push_back(NextState(twin_first->result(), m));
    }
    // SIGTERM: the server drains, writes a snapshot per session and exits 0; the streams end.
    ASSERT_EQ(server->StopWith(SIGTERM), 0);
    for (const std::string& id : ids) {
      EXPECT_TRUE(std::filesystem::exists(state_dir_ / absl::StrCat(id, ".snapshot"))) << id;
    }
    for (auto& stream : streams) stream->Close();
  }

  server = Start(port, /*with_state_dir=*/true);
  const std::shared_ptr<grpc::Channel> channel = OpenChannel(server->target());
  for (std::size_t i = 0; i < kinds.size(); ++i) {
    const int m = static_cast<int>(kinds[i].spec.model().num_states());
    ControlStream reattached(channel, ids[i]);
    absl::StatusOr<v1::ControlResponse> answer = reattached.First(nullptr, ids[i], states[i]);
    ASSERT_TRUE(answer.ok()) << kinds[i].name << ": " << answer.status();
    EXPECT_EQ(answer->session_id(), ids[i]);
    for (int k = 0; k < kStepsAfter; ++k) {
      absl::StatusOr<v1::ControlResponse> twin = twins[i]->Step(states[i]);
      ASSERT_TRUE(twin.ok()) << kinds[i].name;
      ExpectSamePlan(answer->result(), twin->result(), absl::StrCat(kinds[i].name, " after, step ", k));
      states[i] = NextState(twin->result(), m);
      if (k + 1 < kStepsAfter) answer = reattached.Step(states[i]);
      ASSERT_TRUE(answer.ok()) << kinds[i].name;
    }
    reattached.Close();
    EXPECT_FALSE(std::filesystem::exists(state_dir_ / absl::StrCat(ids[i], ".snapshot"))) << "claimed, so removed";
  }
  for (auto& twin : twins) twin->Close();
  EXPECT_EQ(server->StopWith(SIGTERM), 0);
}

TEST_F(RestartReattachTest, AnUnknownIdAndAnotherSessionsFileAreNotRestoredAndTheRestIs) {
  const int port = FreeLoopbackPort();
  std::unique_ptr<ServerProcess> server = Start(port, /*with_state_dir=*/true);
  const v1::ProblemSpec spec = Masses();
  std::string id;
  {
    ControlStream stream(OpenChannel(server->target()));
    absl::StatusOr<v1::ControlResponse> first = stream.First(&spec, "", InitialState(spec));
    ASSERT_TRUE(first.ok()) << first.status();
    id = first->session_id();
    ASSERT_EQ(server->StopWith(SIGTERM), 0);
    stream.Close();
  }
  // Garbage under another id, and a copy of the good file truncated under a third.
  const std::string garbage_id(32, 'b'), truncated_id(32, 'c');
  const std::filesystem::path good = state_dir_ / absl::StrCat(id, ".snapshot");
  ASSERT_TRUE(std::filesystem::exists(good));
  std::filesystem::copy_file(good, state_dir_ / absl::StrCat(truncated_id, ".snapshot"));
  std::filesystem::resize_file(state_dir_ / absl::StrCat(truncated_id, ".snapshot"),
                               std::filesystem::file_size(good) / 2);
  std::filesystem::copy_file(good, state_dir_ / absl::StrCat(garbage_id, ".snapshot"));
  std::filesystem::resize_file(state_dir_ / absl::StrCat(garbage_id, ".snapshot"), 0);
  server = Start(port, /*with_state_dir=*/true);
  // Skipped (an error line names each) and left in place; the server serves the rest.
  const std::shared_ptr<grpc::Channel> channel = OpenChannel(server->target());
  for (const std::string& missing : {truncated_id, garbage_id, std::string(32, 'd')}) {
    ControlStream stream(channel, missing);
    EXPECT_FALSE(stream.First(nullptr, missing, InitialState(spec)).ok()) << missing;
  }
  ControlStream stream(channel, id);
  absl::StatusOr<v1::ControlResponse> answer = stream.First(nullptr, id, InitialState(spec));
  ASSERT_TRUE(answer.ok()) << answer.status();
  EXPECT_TRUE(answer->result().has_plan());
  stream.Close();
  EXPECT_EQ(server->StopWith(SIGTERM), 0);
}

TEST_F(RestartReattachTest, ClosingASessionLeftInTheStateDirectoryDiscardsItsSnapshot) {
  const int port = FreeLoopbackPort();
  std::unique_ptr<ServerProcess> server = Start(port, /*with_state_dir=*/true);
  const v1::ProblemSpec spec = Masses();
  std::string id;
  {
    // A session of unary calls (a stream's is re-attached only by a stream).
    auto stub = v1::MpcService::NewStub(OpenChannel(server->target()));
    grpc::ClientContext create_context;
    v1::CreateSessionRequest create;
    *create.mutable_spec() = spec;
    v1::CreateSessionResponse created;
    ASSERT_TRUE(stub->CreateSession(&create_context, create, &created).ok());
    id = created.session_id();
  }
  ASSERT_EQ(server->StopWith(SIGTERM), 0);
  const std::filesystem::path file = state_dir_ / absl::StrCat(id, ".snapshot");
  ASSERT_TRUE(std::filesystem::exists(file));

  server = Start(port, /*with_state_dir=*/true);
  auto stub = v1::MpcService::NewStub(OpenChannel(server->target()));
  const auto close = [&] {
    grpc::ClientContext context;
    v1::CloseSessionRequest request;
    request.set_session_id(id);
    v1::CloseSessionResponse response;
    return stub->CloseSession(&context, request, &response);
  };
  const grpc::Status closed = close();
  EXPECT_TRUE(closed.ok()) << closed.error_message();
  EXPECT_FALSE(std::filesystem::exists(file));
  // Gone: neither closed again nor solved.
  EXPECT_EQ(close().error_code(), grpc::StatusCode::NOT_FOUND);
  grpc::ClientContext solve_context;
  v1::SolveRequest solve;
  solve.set_session_id(id);
  const std::vector<double> x0 = InitialState(spec);
  solve.mutable_step()->mutable_state()->Assign(x0.begin(), x0.end());
  v1::SolveResponse solved;
  EXPECT_EQ(stub->Solve(&solve_context, solve, &solved).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(server->StopWith(SIGTERM), 0);
}

}  // namespace
}  // namespace nupmpc::testing
