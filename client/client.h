#ifndef NUPMPC_CLIENT_CLIENT_H_
#define NUPMPC_CLIENT_CLIENT_H_

// C++ client of nupmpc.v1.MpcService.
//
//   nupmpc::Client client("127.0.0.1:50051");
//   auto session = client.OpenSession(spec);          // a Control stream owning a session
//   v1::Step step;  step.add_state(...);               // measured x[0]
//   auto result = (*session)->Step(step);              // u = result->inputs() (N×L)
//
// A Session survives a server restart, and the loss of its replica behind a balancer:
// when its stream breaks (UNAVAILABLE, a cancellation it did not make, or a stream that
// ended without a status, as a balancer ends those of a dead replica) it reconnects with exponential back-off and
// jitter within a budget (ReconnectOptions, default 50 ms doubling to 2 s, ±20 %, 30 s), attaches to its session by
// id (a server that kept it, or restored it from a snapshot, hands it back warm), else re-creates the session from
// the spec it holds (kept current with every answered step by ApplyStepToSpec, client/spec_update.h: state, references,
// bounds, shifts, GP reference, Δu's u[-1]; the warm start is lost, nothing else), and resends the step, so Step()
// returns that step's result. Only when the budget is spent does Step() fail, with UNAVAILABLE.
// With a control period (OpenSession's ControlPeriod, client/session.h) a step instead
// returns by its period, HELD (no plan) when the answer did not come in time, and the
// session reconnects in the background for as long as the caller keeps stepping.
//
// Apply a result's inputs only when HasPlan(result): a result without a plan (CANCELLED,
// SUPERSEDED, HELD, or a TIME_LIMIT / NUMERICAL_ERROR before any finite iterate) carries no
// inputs for this step's state; hold the last applied input (or a safe one) instead.
// A result with a plan but another status than CONVERGED (ITERATION_LIMIT, INFEASIBLE,
// ...) is still this step's plan: apply it and look at the status.

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/channel_security.h"
#include "client/reconnect.h"
#include "client/session.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc {

// Whether `result` carries a plan for the state of its step (SolveResult.has_plan): the
// only results whose inputs a controller may apply.
inline bool HasPlan(const v1::SolveResult& result) { return result.has_plan(); }

class Client {
 public:
  // `target` is host:port. Calls without an explicit deadline use `default_deadline`
  // (0 = none).
  explicit Client(const std::string& target, std::chrono::milliseconds default_deadline = std::chrono::milliseconds(0));
  explicit Client(std::shared_ptr<grpc::Channel> channel,
                  std::chrono::milliseconds default_deadline = std::chrono::milliseconds(0));
  // A client of a server with TLS, mTLS or bearer tokens (client/channel_security.h);
  // an error naming the option when a file cannot be read or a token would go out in
  // clear text.
  static absl::StatusOr<std::unique_ptr<Client>> Connect(
      const std::string& target, const ChannelSecurity& security,
      std::chrono::milliseconds default_deadline = std::chrono::milliseconds(0));

  absl::StatusOr<v1::SolveResult> SolveOnce(const v1::ProblemSpec& spec);
  // Creates a session under `session_id` (empty: a new random id, NewSessionId). This and
  // every call below that names a session carry the id in the x-nupmpc-session header, so
  // a balancer that routes by it sends them all to the replica holding the session
  // (client/session_routing.h). AddressedSession adds failover on top.
  absl::StatusOr<v1::CreateSessionResponse> CreateSession(const v1::ProblemSpec& spec, std::string session_id = {});
  absl::StatusOr<v1::SolveResult> Solve(const std::string& session_id, const v1::Step& step);
  // Steps many sessions in one call (SolveFleetRequest): one answer per step, in order, each
  // a result or an error of its own. Not routed by session: all of them must live on the
  // replica this client reaches.
  absl::StatusOr<v1::SolveFleetResponse> SolveFleet(const v1::SolveFleetRequest& request);
  absl::StatusOr<v1::GetServerInfoResponse> GetServerInfo();
  absl::StatusOr<v1::FitGpModelResponse> FitGpModel(const v1::FitGpModelRequest& request);
  absl::StatusOr<v1::SessionInfo> GetSession(const std::string& session_id);
  absl::StatusOr<std::vector<v1::SessionInfo>> ListSessions();
  absl::Status CloseSession(const std::string& session_id);

  // Opens a Control stream that creates (and owns) a session for `spec`. The first attach
  // is tried once (a wrong address or spec fails at once); `reconnect` governs what
  // happens when the stream breaks later, `period` how long a step may take (session.h).
  absl::StatusOr<std::unique_ptr<Session>> OpenSession(const v1::ProblemSpec& spec, ReconnectOptions reconnect = {},
                                                       ControlPeriod period = {});

  v1::MpcService::Stub& stub() { return *stub_; }

 private:
  void SetDeadline(grpc::ClientContext* context) const;
  // One blocking unary call with the default deadline, routed to `session_id`'s replica
  // when not empty.
  template <typename Request, typename Response>
  absl::StatusOr<Response> Unary(grpc::Status (v1::MpcService::Stub::*method)(grpc::ClientContext*, const Request&,
                                                                              Response*),
                                 const Request& request, const std::string& session_id = {});
  // A new channel to target_ with credentials_ (`own_subchannel`: a connection of its own).
  std::shared_ptr<grpc::Channel> NewChannel(bool own_subchannel) const;
  std::string target_;  // empty when built from a channel
  std::shared_ptr<grpc::ChannelCredentials> credentials_;
  ChannelSecurity security_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::MpcService::Stub> stub_;
  std::chrono::milliseconds default_deadline_;
  friend class Session;
  friend class AddressedSession;
};

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_CLIENT_H_
