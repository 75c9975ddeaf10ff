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
// now leads, and no snapshot of it either) is as good a reason to re-create it as a lost
// replica.
absl::Status AsFailoverCause(const absl::Status& s) {
  if (!absl::IsNotFound(s)) return s;
  return absl::UnavailableError(absl::StrCat(s.message(), " (the session is not on the replica that answered)"));
}

// Closing is best effort for a replica that may be gone: never wait long.
constexpr std::chrono::milliseconds kCloseTimeout{2000};

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
  if (!s.ok()) {
    return absl::Status(static_cast<absl::StatusCode>(s.error_code()),
                        absl::StrCat("CreateSession: ", s.error_message()));
  }
  if (response.session_id() != request.session_id()) {
    // A server from before CreateSessionRequest.session_id drew its own id: a balancer would
    // send the later calls elsewhere, and every step would re-create the session.
    (void)CloseById(response.session_id());
    return absl::FailedPreconditionError(
        "CreateSession: the server ignores CreateSessionRequest.session_id (an older server); addressed sessions "
        "need it");
  }
  id_ = response.session_id();
  return absl::OkStatus();
}

absl::StatusOr<v1::SolveResult> AddressedSession::SolveLocked(const v1::Step& step, std::chrono::milliseconds timeout) {
  if (id_.empty()) return absl::FailedPreconditionError("the session is closed");
  v1::SolveRequest request;
  request.set_session_id(id_);
  *request.mutable_step() = step;
  grpc::ClientContext context;
  SetTimeout(&context, timeout);
  RouteToSession(&context, id_);
  v1::SolveResponse response;
  const grpc::Status s = client_->stub().Solve(&context, request, &response);
  if (!s.ok()) {
    return absl::Status(static_cast<absl::StatusCode>(s.error_code()), absl::StrCat("Solve: ", s.error_message()));
  }
  return std::move(*response.mutable_result());
}

absl::Status AddressedSession::CloseById(const std::string& id) {
  v1::CloseSessionRequest request;
  request.set_session_id(id);
  grpc::ClientContext context;
  SetTimeout(&context, kCloseTimeout);
  RouteToSession(&context, id);
  v1::CloseSessionResponse response;
  const grpc::Status s = client_->stub().CloseSession(&context, request, &response);
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
}

absl::StatusOr<v1::SolveResult> AddressedSession::Step(const v1::Step& step) {
  std::lock_guard<std::mutex> lock(mu_);
  // A step that failed without an answer may have been applied by the server, so the spec
  // held for re-creating the session may lag behind it: a step that keeps the previous
  // state ("empty keeps it") is then refused rather than re-created from an older state.
  if (spec_may_lag_ && step.state().empty()) {
    return absl::FailedPreconditionError(
        "Step.state: empty after a step that failed; send the measured state (the session may have to be "
        "re-created, and its last state is not known for sure)");
  }
  absl::StatusOr<v1::SolveResult> result = SolveLocked(step, client_->default_deadline_);
  const bool lost = absl::IsNotFound(result.status());
  if (!result.ok() && (IsRetryable(result.status()) || lost) && !id_.empty()) {
    const absl::Status outage = RideOutOutage(
        reconnect_, lost ? AsFailoverCause(result.status()) : result.status(),
        [&](std::chrono::milliseconds timeout, ReconnectAttempt* report, bool* answered) -> absl::Status {
          // A direct connection refused while its server restarted would wait out gRPC's
          // own back-off (seconds) before the next call may connect.
          grpc::experimental::ChannelResetConnectionBackoff(client_->channel_.get());
          absl::Status back = ReattachOrRecreate(
              // NOT_FOUND from the start: the replica the id leads to has neither the
              // session nor its snapshot, so asking again by the id cannot help.
              lost ? std::string() : id_,
              [&] {
                // The step itself asks for the session by its id: a server that came back
                // with it (restored from its snapshot) answers it, warm. An answer that is
                // an error of the step's own also means the session was there.
                result = SolveLocked(step, timeout);
                const bool reached =
                    result.ok() || (!IsRetryable(result.status()) && !AttachByIdMissed(result.status()));
                return reached ? absl::OkStatus() : result.status();
              },
              [&] {
                if (absl::Status s = CreateLocked(timeout); !s.ok()) return s;
                result = SolveLocked(step, timeout);
                if (result.ok() || (!IsRetryable(result.status()) && !absl::IsNotFound(result.status()))) {
                  return absl::OkStatus();
                }
                // Not answered: the next attempt makes another session; do not leave this
                // one holding memory on its replica until it expires.
                (void)CloseById(id_);
                return AsFailoverCause(result.status());
              },
              report);
          if (!back.ok()) return back;
          *answered = true;
          return result.status();
        },
        &stats_);
    if (!outage.ok()) result = outage;
  }
  if (result.ok()) {
    ApplyStepToSpec(step, *result, &spec_);
    if (!step.state().empty()) spec_may_lag_ = false;
  } else if (!absl::IsInvalidArgument(result.status()) && !absl::IsFailedPrecondition(result.status())) {
    // Those two are refusals before anything changed; after others the step may have been
    // applied (e.g. a deadline during the solve).
    spec_may_lag_ = true;
  }
  return result;
}

absl::Status AddressedSession::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  if (id_.empty()) return absl::OkStatus();
  return CloseById(std::exchange(id_, std::string()));
}

}  // namespace nupmpc
