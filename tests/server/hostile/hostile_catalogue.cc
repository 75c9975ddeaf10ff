#include "tests/server/hostile/hostile_catalogue.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "client/channel_factory.h"
#include "gmock/gmock.h"

namespace nupmpc::testing {
namespace {

constexpr char kService[] = "/nupmpc.v1.MpcService/";
// Resident memory may grow by what a few sessions and gRPC's buffers take; a case that
// allocated by a hostile dimension would take far more.
constexpr std::uint64_t kRssJump = std::uint64_t{256} << 20;

// Drains a completion queue after its last tag (required before destroying it).
void ShutDownQueue(grpc::CompletionQueue* queue) {
  queue->Shutdown();
  void* tag = nullptr;
  bool ok = false;
  while (queue->Next(&tag, &ok)) {
  }
}

}  // namespace

grpc::Status CallWithBytes(const std::string& target, const std::string& method, const std::string& bytes) {
  grpc::GenericStub stub(nupmpc::OpenChannel(target));
  grpc::CompletionQueue queue;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  grpc::Slice slice(bytes);
  const grpc::ByteBuffer request(&slice, 1);
  std::unique_ptr<grpc::GenericClientAsyncResponseReader> call =
      stub.PrepareUnaryCall(&context, kService + method, request, &queue);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  EXPECT_TRUE(queue.Next(&tag, &ok));
  ShutDownQueue(&queue);
  return status;
}

RawControlStream::RawControlStream(const std::string& target)
    : stub_(std::make_unique<grpc::GenericStub>(nupmpc::OpenChannel(target))) {
  context_.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  stream_ = stub_->PrepareCall(&context_, std::string(kService) + "Control", &queue_);
  stream_->StartCall(nullptr);
  EXPECT_TRUE(Next());
}

RawControlStream::~RawControlStream() { ShutDownQueue(&queue_); }

bool RawControlStream::Next() {
  void* tag = nullptr;
  bool ok = false;
  EXPECT_TRUE(queue_.Next(&tag, &ok));
  return ok;
}

bool RawControlStream::Write(const std::string& bytes) {
  grpc::Slice slice(bytes);
  stream_->Write(grpc::ByteBuffer(&slice, 1), nullptr);
  return Next();
}

bool RawControlStream::Read(std::string* bytes) {
  grpc::ByteBuffer answer;
  stream_->Read(&answer, nullptr);
  if (!Next()) return false;
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(answer.Dump(&slices).ok());
  bytes->clear();
  for (const grpc::Slice& s : slices) bytes->append(reinterpret_cast<const char*>(s.begin()), s.size());
  return true;
}

grpc::Status RawControlStream::Finish() {
  stream_->WritesDone(nullptr);
  Next();  // fails when the server already ended the stream
  grpc::Status status;
  stream_->Finish(&status, nullptr);
  Next();
  return status;
}

grpc::Status ControlWithBytes(const std::string& target, const std::string& bytes) {
  RawControlStream stream(target);
  stream.Write(bytes);
  std::string answer;
  EXPECT_FALSE(stream.Read(&answer)) << "the stream answered a message it could not parse";
  return stream.Finish();
}

void HostileCatalogueTest::SetUp() {
  ServiceTest::SetUp();
  instance_ = LoadInstanceOrDie("masses_N30");
  spec_ = SpecOrDie(instance_.problem);
  CreateHealthySession();
}

void HostileCatalogueTest::CreateHealthySession() {
  auto healthy = client_->CreateSession(spec_);
  ASSERT_TRUE(healthy.ok()) << healthy.status();
  healthy_id_ = healthy->session_id();
  auto before = client_->Solve(healthy_id_, StateStep(4));
  ASSERT_TRUE(before.ok()) << before.status();
  healthy_result_ = *before;
  rss_before_ = Rss();
}

void HostileCatalogueTest::RestartServer(server::ServerOptions options, const std::string& token) {
  client_.reset();
  server_->Shutdown();
  StartServer(options);
  if (!token.empty()) {
    ChannelSecurity security;
    security.token = token;
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(target_, security, std::chrono::seconds(30));
    ASSERT_TRUE(client.ok()) << client.status();
    client_ = *std::move(client);
  }
  CreateHealthySession();
}

v1::Step HostileCatalogueTest::StateStep(int t) const {
  v1::Step step;
  const Eigen::VectorXd& x = instance_.closed_loop->x1[t];
  step.mutable_state()->Add(x.data(), x.data() + x.size());
  step.set_warm_start(v1::WARM_START_COLD);
  return step;
}

std::uint64_t HostileCatalogueTest::Rss() {
  auto info = client_->GetServerInfo();
  EXPECT_TRUE(info.ok()) << info.status();
  return info.ok() ? info->resident_memory_bytes() : 0;
}

void HostileCatalogueTest::ExpectServerUnharmed() {
  auto again = client_->Solve(healthy_id_, StateStep(4));
  ASSERT_TRUE(again.ok()) << again.status();
  ExpectHealthyPlan(*again);
  EXPECT_LT(Rss(), rss_before_ + kRssJump) << "resident memory jumped";
}

void HostileCatalogueTest::ExpectHealthyPlan(const v1::SolveResult& result) const {
  EXPECT_EQ(result.objective(), healthy_result_.objective());
  ASSERT_EQ(result.inputs_size(), healthy_result_.inputs_size());
  for (int i = 0; i < result.inputs_size(); ++i) EXPECT_EQ(result.inputs(i), healthy_result_.inputs(i)) << i;
}

void HostileCatalogueTest::ExpectFinite(const v1::SolveResult& r) {
  for (double v : r.inputs()) EXPECT_TRUE(std::isfinite(v));
  for (double v : r.states()) EXPECT_TRUE(std::isfinite(v));
  for (double v : r.outputs()) EXPECT_TRUE(std::isfinite(v));
  EXPECT_TRUE(std::isfinite(r.objective()) || !r.has_plan());
}

void HostileCatalogueTest::ExpectRefused(const absl::Status& status, absl::StatusCode code, const std::string& field) {
  EXPECT_EQ(status.code(), code) << status;
  EXPECT_THAT(std::string(status.message()), ::testing::HasSubstr(field)) << status;
}

void HostileCatalogueTest::ExpectRefused(const grpc::Status& status, grpc::StatusCode code, const std::string& field) {
  EXPECT_EQ(status.error_code(), code) << status.error_message();
  EXPECT_THAT(status.error_message(), ::testing::HasSubstr(field));
}

std::unique_ptr<OpenStream> HostileCatalogueTest::OpenControl(const v1::ControlRequest& first,
                                                              v1::ControlResponse* answer, bool* answered) {
  auto s = std::make_unique<OpenStream>();
  s->context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  s->stream = client_->stub().Control(&s->context);
  EXPECT_TRUE(s->stream->Write(first));
  *answered = s->stream->Read(answer);
  return s;
}

grpc::Status HostileCatalogueTest::EndStream(OpenStream* s) {
  s->stream->WritesDone();
  v1::ControlResponse ignored;
  while (s->stream->Read(&ignored)) {
  }
  return s->stream->Finish();
}

void HostileCatalogueTest::CountCases(const std::string& hostile_class, int cases) {
  std::printf("hostile catalogue: %s: %d cases\n", hostile_class.c_str(), cases);
  RecordProperty("cases." + hostile_class, cases);
}

}  // namespace nupmpc::testing
