// The hostile-input catalogue's transport classes: messages over
// --max_message_bytes (RESOURCE_EXHAUSTED from gRPC before anything is parsed, in either
// direction), and bytes that are no message of the method's type, sent to every RPC
// (INVALID_ARGUMENT naming the expected type). After each case a healthy session answers
// with the bit-identical plan and resident memory has not jumped.
#include <chrono>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "tests/server/hostile/hostile_catalogue.h"

namespace nupmpc::testing {
namespace {

using G = grpc::StatusCode;

// Every method of MpcService and its request type.
struct Method {
  const char* name;
  const char* request;
};
constexpr Method kMethods[] = {
    {"CreateSession", "nupmpc.v1.CreateSessionRequest"},
    {"Solve", "nupmpc.v1.SolveRequest"},
    {"SolveOnce", "nupmpc.v1.SolveOnceRequest"},
    {"GetSession", "nupmpc.v1.GetSessionRequest"},
    {"ListSessions", "nupmpc.v1.ListSessionsRequest"},
    {"CloseSession", "nupmpc.v1.CloseSessionRequest"},
    {"GetServerInfo", "nupmpc.v1.GetServerInfoRequest"},
    {"FitGpModel", "nupmpc.v1.FitGpModelRequest"},
    {"Control", "nupmpc.v1.ControlRequest"},
};

grpc::Status SendBytes(const std::string& target, const Method& method, const std::string& bytes) {
  if (std::string(method.name) == "Control") return ControlWithBytes(target, bytes);
  return CallWithBytes(target, method.name, bytes);
}

class HostileTransportTest : public HostileCatalogueTest {};

TEST_F(HostileTransportTest, MessagesOverTheLimitAreResourceExhaustedOnEveryMethod) {
  server::ServerOptions options = DefaultOptions();
  options.max_message_bytes = 1 << 20;
  RestartServer(options);
  // A valid request prefix (a spec's model) grown past the limit: the size alone refuses it.
  v1::SolveOnceRequest big;
  *big.mutable_spec() = spec_;
  big.mutable_spec()->mutable_model()->mutable_output_offset()->Resize(200000, 0.0);
  const std::string oversized = big.SerializeAsString();
  ASSERT_GT(oversized.size(), std::size_t{1} << 20);
  int cases = 0;
  for (const Method& m : kMethods) {
    SCOPED_TRACE(m.name);
    ExpectRefused(SendBytes(target_, m, oversized), G::RESOURCE_EXHAUSTED, "larger than max");
    ExpectServerUnharmed();
    ++cases;
  }
  // Through the client library as well.
  ExpectRefused(client_->SolveOnce(big.spec()).status(), absl::StatusCode::kResourceExhausted, "larger than max");
  ExpectServerUnharmed();
  ++cases;
  {  // mid-stream: the stream ends and its session closes
    const int sessions = server_->state().registry.size();
    v1::ControlRequest open;
    *open.mutable_spec() = spec_;
    v1::ControlResponse hello;
    bool answered = false;
    std::unique_ptr<OpenStream> s = OpenControl(open, &hello, &answered);
    ASSERT_TRUE(answered);
    v1::ControlRequest huge;
    huge.mutable_step()->mutable_state()->Resize(200000, 0.0);
    s->stream->Write(huge);
    ExpectRefused(EndStream(s.get()), G::RESOURCE_EXHAUSTED, "larger than max");
    for (int i = 0; i < 500 && server_->state().registry.size() != sessions; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_EQ(server_->state().registry.size(), sessions);
    ExpectServerUnharmed();
    ++cases;
  }
  {  // an answer over the limit: a plan over a horizon of 100000 steps of a scalar system
    v1::ProblemSpec long_plan;
    v1::Model* model = long_plan.mutable_model();
    model->set_num_states(1);
    model->set_num_inputs(1);
    model->set_horizon(100000);
    for (v1::Matrix* m : {model->add_a(), model->add_b()}) {
      m->set_rows(1);
      m->set_cols(1);
      m->add_data(0.5);
    }
    long_plan.mutable_initial_state()->add_mean(1.0);
    long_plan.add_input_priors()->add_weight(1.0);
    ExpectRefused(client_->SolveOnce(long_plan).status(), absl::StatusCode::kResourceExhausted, "max");
    ExpectServerUnharmed();
    ++cases;
  }
  CountCases("oversized messages", cases);
}

TEST_F(HostileTransportTest, BytesThatAreNoMessageAreInvalidArgumentOnEveryMethod) {
  std::string random_bytes;
  for (int i = 0; i < 4096; ++i) random_bytes.push_back(static_cast<char>((i * 7919 + 13) % 251));
  struct Bytes {
    const char* kind;
    std::string bytes;
  };
  const Bytes patterns[] = {
      {"random", random_bytes},
      {"a length past the end", "\x0a\xff\xff\xff\xff\x0f"},
      {"an invalid wire type", "\x0f\x01"},
      {"groups nested 100000 deep", std::string(100000, '\x0b')},
  };
  int cases = 0;
  for (const Method& m : kMethods) {
    for (const Bytes& b : patterns) {
      SCOPED_TRACE(absl::StrCat(m.name, ": ", b.kind));
      ExpectRefused(SendBytes(target_, m, b.bytes), G::INVALID_ARGUMENT, m.request);
      ExpectServerUnharmed();
      ++cases;
    }
  }
  CountCases("random bytes", cases);
}

}  // namespace
}  // namespace nupmpc::testing
