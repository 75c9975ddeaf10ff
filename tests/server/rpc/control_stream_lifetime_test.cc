// Control streams that end while their solve is queued or running: the stream's reactor
// must outlive the worker's task (otherwise a worker touches a stream that a gRPC thread
// has already deleted). Under AddressSanitizer (deploy/test-sanitizers.sh) any access to a
// freed stream fails the test; in every build the server must go on serving and close
// every session the streams created.
#include <chrono>
#include <memory>
#include <thread>
#include <vector>

#include "client/channel_factory.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

enum class Ending { kHalfCloseAfterTheAnswer, kHalfCloseAtOnce, kCancelAtOnce };

// One stream: creates its session with the first step, then ends as `ending` says.
void RunShortStream(v1::MpcService::Stub& stub, const v1::ControlRequest& first, Ending ending) {
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReaderWriter<v1::ControlRequest, v1::ControlResponse>> stream = stub.Control(&context);
  ASSERT_TRUE(stream->Write(first));
  v1::ControlResponse response;
  switch (ending) {
    case Ending::kHalfCloseAfterTheAnswer:
      ASSERT_TRUE(stream->Read(&response));
      EXPECT_EQ(response.result().status(), v1::SOLVE_STATUS_CONVERGED);
      stream->WritesDone();
      break;
    case Ending::kHalfCloseAtOnce:
      stream->WritesDone();
      break;
    case Ending::kCancelAtOnce:
      context.TryCancel();
      break;
  }
  while (stream->Read(&response)) {
  }
  (void)stream->Finish();
}

TEST_F(ServiceTest, StreamsEndingWhileTheirSolveIsQueuedOrRunningLeaveNothingBehind) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  v1::ControlRequest first;
  *first.mutable_spec() = SpecOrDie(inst.problem);  // IFFBDD: the sessions that crashed
  const Eigen::VectorXd& x = inst.closed_loop->x1[0];
  first.mutable_step()->mutable_state()->Add(x.data(), x.data() + x.size());
  constexpr int kThreads = 4, kStreamsPerThread = 30;
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      const std::shared_ptr<grpc::Channel> channel = nupmpc::OpenChannel(target_);
      const std::unique_ptr<v1::MpcService::Stub> stub = v1::MpcService::NewStub(channel);
      for (int i = 0; i < kStreamsPerThread; ++i) RunShortStream(*stub, first, static_cast<Ending>((t + i) % 3));
    });
  }
  for (std::thread& t : threads) t.join();

  // Sessions owned by streams close in OnDone, which may still be running for the last ones.
  absl::StatusOr<v1::GetServerInfoResponse> info;
  for (int i = 0; i < 200; ++i) {
    info = client_->GetServerInfo();
    ASSERT_TRUE(info.ok()) << info.status();
    if (info->active_sessions() == 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(info->active_sessions(), 0u) << "sessions of ended streams were left behind";
  absl::StatusOr<v1::SolveResult> after = client_->SolveOnce(first.spec());
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_EQ(after->status(), v1::SOLVE_STATUS_CONVERGED);
}

// A stream that ends by itself (the client half-closes, or the server ends it) closes the
// session it created before it sends its status: a client holding the status neither lists
// nor counts that session any more (it would, for a moment, when the session closed only in
// OnDone, after the status).
TEST_F(ServiceTest, AStreamsOwnSessionIsClosedBeforeTheClientHasTheStreamsStatus) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  v1::ControlRequest first;
  *first.mutable_spec() = SpecOrDie(inst.problem);
  const Eigen::VectorXd& x = inst.closed_loop->x1[0];
  first.mutable_step()->mutable_state()->Add(x.data(), x.data() + x.size());
  const std::unique_ptr<v1::MpcService::Stub> stub = v1::MpcService::NewStub(nupmpc::OpenChannel(target_));
  for (int i = 0; i < 20; ++i) {
    RunShortStream(*stub, first, Ending::kHalfCloseAfterTheAnswer);
    absl::StatusOr<v1::GetServerInfoResponse> info = client_->GetServerInfo();
    ASSERT_TRUE(info.ok()) << info.status();
    ASSERT_EQ(info->active_sessions(), 0u) << "stream " << i << ": its session was still open after its status";
    absl::StatusOr<std::vector<v1::SessionInfo>> listed = client_->ListSessions();
    ASSERT_TRUE(listed.ok()) << listed.status();
    ASSERT_TRUE(listed->empty()) << "stream " << i;
  }
}

}  // namespace
}  // namespace nupmpc::testing
