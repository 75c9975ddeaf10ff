#ifndef NUPMPC_CLIENT_CLIENT_H_
#define NUPMPC_CLIENT_CLIENT_H_

// C++ client of nupmpc.v1.MpcService.
//
//   nupmpc::Client client("localhost:50051");
//   auto session = client.OpenSession(spec);          // a Control stream owning a session
//   v1::Step step;  step.add_state(...);               // measured x[0]
//   auto result = (*session)->Step(step);              // u = result->inputs() (N×L)
//
// A Session survives a server restart: when its stream breaks it reconnects, re-creates
// the session from the spec it holds (with every update sent so far applied), and resends
// the step, so the caller's next Step() succeeds (the warm start is lost, nothing else).

#include <chrono>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc {

class Session;

class Client {
 public:
  // `target` is host:port. Calls without an explicit deadline use `default_deadline`
  // (0 = none).
  explicit Client(const std::string& target,
                  std::chrono::milliseconds default_deadline = std::chrono::milliseconds(0));
  explicit Client(std::shared_ptr<grpc::Channel> channel,
                  std::chrono::milliseconds default_deadline = std::chrono::milliseconds(0));

  absl::StatusOr<v1::SolveResult> SolveOnce(const v1::ProblemSpec& spec);
  absl::StatusOr<v1::CreateSessionResponse> CreateSession(const v1::ProblemSpec& spec);
  absl::StatusOr<v1::SolveResult> Solve(const std::string& session_id, const v1::Step& step);
  absl::StatusOr<v1::GetServerInfoResponse> GetServerInfo();
  absl::StatusOr<v1::FitGpModelResponse> FitGpModel(const v1::FitGpModelRequest& request);
  absl::StatusOr<v1::SessionInfo> GetSession(const std::string& session_id);
  absl::StatusOr<std::vector<v1::SessionInfo>> ListSessions();
  absl::Status CloseSession(const std::string& session_id);

  // Opens a Control stream that creates (and owns) a session for `spec`.
  absl::StatusOr<std::unique_ptr<Session>> OpenSession(const v1::ProblemSpec& spec);

  v1::MpcService::Stub& stub() { return *stub_; }

 private:
  void SetDeadline(grpc::ClientContext* context) const;
  // One blocking unary call with the default deadline.
  template <typename Request, typename Response>
  absl::StatusOr<Response> Unary(
      grpc::Status (v1::MpcService::Stub::*method)(grpc::ClientContext*, const Request&, Response*),
      const Request& request);
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::MpcService::Stub> stub_;
  std::chrono::milliseconds default_deadline_;
  friend class Session;
};

class Session {
 public:
  ~Session();
  // One control period (blocking). Reconnects once if the stream broke.
  absl::StatusOr<v1::SolveResult> Step(const v1::Step& step);
  // The same on a separate thread; steps of one session still run one at a time.
  std::future<absl::StatusOr<v1::SolveResult>> StepAsync(v1::Step step);
  // Ends the stream (the server closes the session).
  absl::Status Close();
  std::string id() const;
  int reconnects() const { return reconnects_; }

 private:
  friend class Client;
  Session(Client* client, v1::ProblemSpec spec) : client_(client), spec_(std::move(spec)) {}
  absl::Status ConnectLocked();
  absl::StatusOr<v1::SolveResult> StepOnceLocked(const v1::Step& step);
  void TearDownLocked();

  Client* client_;
  v1::ProblemSpec spec_;  // kept current with every update sent, for reconnects
  mutable std::mutex mu_;
  std::unique_ptr<grpc::ClientContext> context_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::ControlRequest, v1::ControlResponse>> stream_;
  std::string id_;
  std::uint64_t next_sequence_ = 1;
  int reconnects_ = 0;
};

// Applies a step's update to a spec the way the server applies it to its session
// (shift of per-step arrays, then replaced components). Exposed for tests.
void ApplyUpdateToSpec(const v1::Step& step, v1::ProblemSpec* spec);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_CLIENT_H_
