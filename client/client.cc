#include "client/client.h"

#include <mutex>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/channel_factory.h"
#include "client/session_routing.h"

namespace nupmpc {
namespace {

absl::Status FromGrpc(const grpc::Status& s) {
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
}

// `own_subchannel`: a connection of this channel's own (ChannelOptions.own_connection).
std::shared_ptr<grpc::Channel> MakeChannel(const std::string& target,
                                           const std::shared_ptr<grpc::ChannelCredentials>& credentials,
                                           const ChannelSecurity& security, bool own_subchannel) {
  return OpenChannel(target, credentials, security, ClientChannelOptions(own_subchannel));
}
}  // namespace

Client::Client(const std::string& target, std::chrono::milliseconds default_deadline)
    : Client(MakeChannel(target, grpc::InsecureChannelCredentials(), {}, /*own_subchannel=*/false), default_deadline) {
  target_ = target;
  credentials_ = grpc::InsecureChannelCredentials();
}

absl::StatusOr<std::unique_ptr<Client>> Client::Connect(const std::string& target, const ChannelSecurity& security,
                                                        std::chrono::milliseconds default_deadline) {
  absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> credentials = ChannelCredentialsFor(security, target);
  if (!credentials.ok()) return credentials.status();
  auto client =
      std::make_unique<Client>(MakeChannel(target, *credentials, security, /*own_subchannel=*/false), default_deadline);
  client->target_ = target;
  client->credentials_ = *std::move(credentials);
  client->security_ = security;
  return client;
}

std::shared_ptr<grpc::Channel> Client::NewChannel(bool own_subchannel) const {
  return MakeChannel(target_, credentials_, security_, own_subchannel);
}

Client::Client(std::shared_ptr<grpc::Channel> channel, std::chrono::milliseconds default_deadline)
    : channel_(std::move(channel)), stub_(v1::MpcService::NewStub(channel_)), default_deadline_(default_deadline) {}

void Client::SetDeadline(grpc::ClientContext* context) const {
  if (default_deadline_.count() > 0) context->set_deadline(std::chrono::system_clock::now() + default_deadline_);
}

template <typename Request, typename Response>
absl::StatusOr<Response> Client::Unary(grpc::Status (v1::MpcService::Stub::*method)(grpc::ClientContext*,
                                                                                    const Request&, Response*),
                                       const Request& request, const std::string& session_id) {
  grpc::ClientContext context;
  SetDeadline(&context);
  if (!session_id.empty()) RouteToSession(&context, session_id);
  Response response;
  const grpc::Status s = (stub_.get()->*method)(&context, request, &response);
  if (!s.ok()) return FromGrpc(s);
  return response;
}

absl::StatusOr<v1::SolveResult> Client::SolveOnce(const v1::ProblemSpec& spec) {
  v1::SolveOnceRequest request;
  *request.mutable_spec() = spec;
  auto response = Unary(&v1::MpcService::Stub::SolveOnce, request);
  if (!response.ok()) return response.status();
  return std::move(*response->mutable_result());
}

absl::StatusOr<v1::CreateSessionResponse> Client::CreateSession(const v1::ProblemSpec& spec, std::string session_id) {
  v1::CreateSessionRequest request;
  *request.mutable_spec() = spec;
  request.set_session_id(session_id.empty() ? NewSessionId() : std::move(session_id));
  return Unary(&v1::MpcService::Stub::CreateSession, request, request.session_id());
}

absl::StatusOr<v1::SolveResult> Client::Solve(const std::string& session_id, const v1::Step& step) {
  v1::SolveRequest request;
  request.set_session_id(session_id);
  *request.mutable_step() = step;
  auto response = Unary(&v1::MpcService::Stub::Solve, request, session_id);
  if (!response.ok()) return response.status();
  return std::move(*response->mutable_result());
}

absl::StatusOr<v1::SolveFleetResponse> Client::SolveFleet(const v1::SolveFleetRequest& request) {
  return Unary(&v1::MpcService::Stub::SolveFleet, request);
}

absl::StatusOr<v1::FitGpModelResponse> Client::FitGpModel(const v1::FitGpModelRequest& request) {
  return Unary(&v1::MpcService::Stub::FitGpModel, request);
}

absl::StatusOr<v1::GetServerInfoResponse> Client::GetServerInfo() {
  return Unary(&v1::MpcService::Stub::GetServerInfo, v1::GetServerInfoRequest());
}

absl::StatusOr<v1::SessionInfo> Client::GetSession(const std::string& session_id) {
  v1::GetSessionRequest request;
  request.set_session_id(session_id);
  auto response = Unary(&v1::MpcService::Stub::GetSession, request, session_id);
  if (!response.ok()) return response.status();
  return response->session();
}

absl::StatusOr<std::vector<v1::SessionInfo>> Client::ListSessions() {
  auto response = Unary(&v1::MpcService::Stub::ListSessions, v1::ListSessionsRequest());
  if (!response.ok()) return response.status();
  return std::vector<v1::SessionInfo>(response->sessions().begin(), response->sessions().end());
}

absl::Status Client::CloseSession(const std::string& session_id) {
  v1::CloseSessionRequest request;
  request.set_session_id(session_id);
  return Unary(&v1::MpcService::Stub::CloseSession, request, session_id).status();
}

absl::StatusOr<std::unique_ptr<Session>> Client::OpenSession(const v1::ProblemSpec& spec, ReconnectOptions reconnect,
                                                             ControlPeriod period) {
  std::unique_ptr<Session> session(new Session(this, spec, std::move(reconnect), period));
  {
    std::lock_guard<std::mutex> lock(session->mu_);
    ReconnectAttempt first;  // no id yet: the session is created from the spec
    if (absl::Status s = session->ConnectLocked(session->reconnect_.attempt_timeout, &first); !s.ok()) return s;
  }
  if (period.period.count() > 0) session->reconnector_ = std::thread([s = session.get()] { s->ReconnectLoop(); });
  return session;
}

}  // namespace nupmpc
