#include "client/client.h"

#include <condition_variable>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/session_routing.h"
#include "client/spec_update.h"

namespace nupmpc {
namespace {

absl::Status FromGrpc(const grpc::Status& s) {
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
}

// `own_subchannel`: a connection of this channel's own, not shared through gRPC's global
// subchannel pool with other channels to the same address (and so not sharing their
// reconnect back-off either).
std::shared_ptr<grpc::Channel> MakeChannel(const std::string& target,
                                           const std::shared_ptr<grpc::ChannelCredentials>& credentials,
                                           const ChannelSecurity& security, bool own_subchannel) {
  grpc::ChannelArguments args;
  // Plans of long horizons exceed gRPC's 4 MB default; the server enforces its own limit.
  args.SetMaxReceiveMessageSize(-1);
  args.SetMaxSendMessageSize(-1);
  if (own_subchannel) args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  // HTTP/2 keepalive: a ping every 2 s, also without calls in flight, and the connection
  // closed when one is not answered within 2 s, so a partition or a frozen server is found
  // in seconds rather than by TCP's timers (minutes). nupmpc-server accepts pings this often;
  // the Python client sends the same (client/python/nupmpc/security.py).
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 2000);
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 2000);
  args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  return CreateChannel(target, credentials, security, args);
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

absl::StatusOr<std::unique_ptr<Session>> Client::OpenSession(const v1::ProblemSpec& spec, ReconnectOptions reconnect) {
  std::unique_ptr<Session> session(new Session(this, spec, std::move(reconnect)));
  std::lock_guard<std::mutex> lock(session->mu_);
  if (absl::Status s = session->ConnectLocked(session->reconnect_.attempt_timeout); !s.ok()) return s;
  return session;
}

Session::~Session() { (void)Close(); }

std::string Session::id() const {
  std::lock_guard<std::mutex> lock(mu_);
  return id_;
}

int Session::reconnects() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_.reconnects;
}

ReconnectStats Session::reconnect_stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_;
}

namespace {

// Cancels a call that has not finished within `timeout` (an attach to a server that
// accepts the connection but does not answer, or a connect that hangs).
class CancelAfter {
 public:
  CancelAfter(grpc::ClientContext* context, std::chrono::milliseconds timeout)
      : thread_([this, context, timeout] {
          std::unique_lock<std::mutex> lock(mu_);
          if (!done_changed_.wait_for(lock, timeout, [this] { return done_; })) {
            fired_ = true;
            context->TryCancel();
          }
        }) {}
  // Stops the timer; true if it had already cancelled the call.
  bool Stop() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
    }
    done_changed_.notify_all();
    if (thread_.joinable()) thread_.join();
    return fired_;
  }
  ~CancelAfter() { Stop(); }

 private:
  std::mutex mu_;
  std::condition_variable done_changed_;
  bool done_ = false;
  bool fired_ = false;
  std::thread thread_;
};

}  // namespace

absl::Status Session::ConnectLocked(std::chrono::milliseconds timeout) {
  context_ = std::make_unique<grpc::ClientContext>();
  CancelAfter watchdog(context_.get(), timeout);
  stream_ = stub_->Control(context_.get());
  v1::ControlRequest hello;
  *hello.mutable_spec() = spec_;
  hello.set_sequence(next_sequence_++);
  v1::ControlResponse response;
  const bool attached = stream_->Write(hello) && stream_->Read(&response);
  if (watchdog.Stop()) {
    TearDownLocked();
    return absl::UnavailableError(absl::StrCat("no session within the attempt timeout of ", timeout.count(), " ms"));
  }
  if (!attached) {
    const grpc::Status s = stream_->Finish();
    TearDownLocked();
    return s.ok() ? absl::UnavailableError("the Control stream closed while attaching") : FromGrpc(s);
  }
  if (response.error_code() != 0) {
    TearDownLocked();
    return absl::Status(static_cast<absl::StatusCode>(response.error_code()), response.error_message());
  }
  id_ = response.session_id();
  return absl::OkStatus();
}

void Session::TearDownLocked() {
  if (context_ != nullptr) context_->TryCancel();
  stream_.reset();
  context_.reset();
}

absl::Status Session::BrokenStreamStatusLocked(const char* what) {
  // The call is over (or about to be): read what is left, then its status.
  v1::ControlResponse ignored;
  while (stream_->Read(&ignored)) {
  }
  const grpc::Status s = stream_->Finish();
  TearDownLocked();
  if (s.ok()) return absl::UnavailableError(absl::StrCat("the Control stream ended (", what, ")"));
  // This session never cancels a live stream: CANCELLED here is the server dropping the
  // call (e.g. shutting down past its grace period), as retryable as a lost connection.
  if (s.error_code() == grpc::StatusCode::CANCELLED) {
    return absl::UnavailableError(
        absl::StrCat("the Control stream was cancelled by the server (", what, "): ", s.error_message()));
  }
  // The server ends every stream with a status; UNKNOWN is gRPC's word for a stream that
  // ended without one ("No status received"): what a balancer does to the streams of a
  // replica that died. The session is gone with the replica.
  if (s.error_code() == grpc::StatusCode::UNKNOWN) {
    return absl::UnavailableError(absl::StrCat("the Control stream ended without a status (", what,
                                               "; a balancer whose replica went away?): ", s.error_message()));
  }
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()),
                      absl::StrCat("the Control stream broke (", what, "): ", s.error_message()));
}

absl::StatusOr<v1::SolveResult> Session::StepOnceLocked(const v1::Step& step) {
  if (stream_ == nullptr) return absl::UnavailableError("not connected");
  v1::ControlRequest request;
  const std::uint64_t sequence = next_sequence_++;
  request.set_sequence(sequence);
  *request.mutable_step() = step;
  if (!stream_->Write(request)) return BrokenStreamStatusLocked("write");
  v1::ControlResponse response;
  while (stream_->Read(&response)) {
    if (response.sequence() != sequence) continue;  // an older step superseded by this one
    if (response.error_code() != 0) {
      return absl::Status(static_cast<absl::StatusCode>(response.error_code()), response.error_message());
    }
    return std::move(*response.mutable_result());
  }
  return BrokenStreamStatusLocked("read");
}

absl::StatusOr<v1::SolveResult> Session::Step(const v1::Step& step) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<v1::SolveResult> result = StepOnceLocked(step);
  if (!result.ok() && IsRetryable(result.status())) {
    // The stream (or the server) went away: re-create the session from the spec and
    // resend the step, with back-off, until the budget is spent.
    TearDownLocked();
    const absl::Status outage = RideOutOutage(
        reconnect_, result.status(),
        [&](std::chrono::milliseconds timeout, bool* answered) -> absl::Status {
          // A channel whose connection attempts were refused while the server was down
          // keeps failing calls at once until its own back-off (1 s growing ×1.6 to 2 min)
          // lets it try again: seconds after the server is back. So every attempt is made
          // on a new channel with a connection of its own, which connects now; the session
          // keeps the one that worked. (Built from a channel, the client has no target to
          // open another: then its channel is told to retry now, which gRPC may honour late.)
          if (!client_->target_.empty()) {
            channel_ = client_->NewChannel(/*own_subchannel=*/true);
            stub_ = v1::MpcService::NewStub(channel_);
          } else {
            grpc::experimental::ChannelResetConnectionBackoff(channel_.get());
          }
          if (absl::Status s = ConnectLocked(timeout); !s.ok()) return s;
          result = StepOnceLocked(step);
          *answered = result.ok() || !IsRetryable(result.status());
          return result.status();
        },
        &stats_);
    // Answered: `result` is the resent step's answer (or its own error).
    if (!outage.ok()) result = outage;
  }
  if (result.ok()) ApplyStepToSpec(step, *result, &spec_);
  return result;
}

std::future<absl::StatusOr<v1::SolveResult>> Session::StepAsync(v1::Step step) {
  return std::async(std::launch::async, [this, step = std::move(step)] { return Step(step); });
}

absl::Status Session::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  if (stream_ == nullptr) return absl::OkStatus();
  stream_->WritesDone();
  v1::ControlResponse ignored;
  while (stream_->Read(&ignored)) {
  }
  const grpc::Status s = stream_->Finish();
  stream_.reset();
  context_.reset();
  return FromGrpc(s);
}

}  // namespace nupmpc
