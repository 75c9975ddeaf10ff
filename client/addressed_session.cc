#include "client/addressed_session.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/session_routing.h"
#include "client/spec_update.h"

namespace nupmpc {
namespace {

// What a failed call means for the session: NOT_FOUND (the session is not where its id
// now leads) is as good a reason to re-create it as a lost replica.
absl::Status AsFailoverCause(const grpc::Status& s, const char* what) {
  const auto code = static_cast<absl::StatusCode>(s.error_code());
  if (code == absl::StatusCode::kNotFound) {
    return absl::UnavailableError(absl::StrCat(what, ": the session is not on the replica that answered (",
                                               s.error_message(), ")"));
  }
  return absl::Status(code, absl::StrCat(what, ": ", s.error_message()));
}

void SetTimeout(grpc::ClientContext* context, std::chrono::milliseconds timeout) {
  if (timeout.count() > 0) context->set_deadline(std::chrono::system_clock::now() + timeout);
}

}  // namespace

absl::StatusOr<std::unique_ptr<AddressedSession>> AddressedSession::Create(Client* client, v1::ProblemSpec spec,
                                                                           ReconnectOptions reconnect) {
  std::unique_ptr<AddressedSession> session(new AddressedSession(client, std::move(spec), std::move(reconnect)));
  std::lock_guard<std::mutex> lock(session->mu_);
  if (absl::Status s = session->CreateLocked(session->reconnect_.attempt_timeout); !s.ok()) return s;
  return session;
}

AddressedSession::~AddressedSession() { (void)Close(); }

std::string AddressedSession::id() const {
  std::lock_guard<std::mutex> lock(mu_);
  return id_;
}

ReconnectStats AddressedSession::reconnect_stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_;
}

absl::Status AddressedSession::CreateLocked(std::chrono::milliseconds timeout) {
  v1::CreateSessionRequest request;
  *request.mutable_spec() = spec_;
  request.set_session_id(NewSessionId());
  grpc::ClientContext context;
  SetTimeout(&context, timeout);
  RouteToSession(&context, request.session_id());
  v1::CreateSessionResponse response;
  const grpc::Status s = client_->stub().CreateSession(&context, request, &response);
  if (!s.ok()) return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
  id_ = response.session_id();
  return absl::OkStatus();
}

absl::StatusOr<v1::SolveResult> AddressedSession::SolveLocked(const v1::Step& step,
                                                              std::chrono::milliseconds timeout) {
  if (id_.empty()) return absl::FailedPreconditionError("the session is closed");
  v1::SolveRequest request;
  request.set_session_id(id_);
  *request.mutable_step() = step;
  grpc::ClientContext context;
  SetTimeout(&context, timeout);
  RouteToSession(&context, id_);
  v1::SolveResponse response;
  const grpc::Status s = client_->stub().Solve(&context, request, &response);
  if (!s.ok()) return AsFailoverCause(s, "Solve");
  return std::move(*response.mutable_result());
}

absl::StatusOr<v1::SolveResult> AddressedSession::Step(const v1::Step& step) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<v1::SolveResult> result = SolveLocked(step, client_->default_deadline_);
  if (!result.ok() && IsRetryable(result.status()) && !id_.empty()) {
    const absl::Status outage = RideOutOutage(
        reconnect_, result.status(),
        [&](std::chrono::milliseconds timeout, bool* answered) -> absl::Status {
          // A direct connection refused while its server restarted would wait out gRPC's
          // own back-off (seconds) before the next call may connect.
          grpc::experimental::ChannelResetConnectionBackoff(client_->channel_.get());
          if (absl::Status s = CreateLocked(timeout); !s.ok()) return s;
          result = SolveLocked(step, timeout);
          *answered = result.ok() || !IsRetryable(result.status());
          return result.status();
        },
        &stats_);
    if (!outage.ok()) result = outage;
  }
  if (result.ok()) ApplyStepToSpec(step, *result, &spec_);
  return result;
}

absl::Status AddressedSession::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  if (id_.empty()) return absl::OkStatus();
  const std::string id = std::exchange(id_, std::string());
  return client_->CloseSession(id);
}

}  // namespace nupmpc
