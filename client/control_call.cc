#include "client/control_call.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "client/session_routing.h"
#include "nupmpc/grpc_handover.h"

namespace nupmpc {

absl::Status BrokenControlStreamStatus(const grpc::Status& s) {
  if (s.ok()) return absl::UnavailableError("the Control stream ended");
  // A session waits on a stream only until it cancels it itself: CANCELLED while it waits
  // is the server dropping the call (e.g. shutting down past its grace period) or gRPC
  // ending it for a connection that died (keepalive), as retryable as a lost connection.
  if (s.error_code() == grpc::StatusCode::CANCELLED) {
    return absl::UnavailableError(absl::StrCat("the Control stream was cancelled: ", s.error_message()));
  }
  // The server ends every stream with a status; UNKNOWN is gRPC's word for a stream that
  // ended without one ("No status received"): what a balancer does to the streams of a
  // replica that died. The session is gone with the replica.
  if (s.error_code() == grpc::StatusCode::UNKNOWN) {
    return absl::UnavailableError(absl::StrCat(
        "the Control stream ended without a status (a balancer whose replica went away?): ", s.error_message()));
  }
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()),
                      absl::StrCat("the Control stream broke: ", s.error_message()));
}

ControlCall::ControlCall(std::shared_ptr<grpc::Channel> channel, const v1::ControlRequest& first)
    : channel_(std::move(channel)), stub_(v1::MpcService::NewStub(channel_)) {
  // A stream attaching by id goes where the id's other calls go: a balancer that routes by
  // the header sends it to the replica holding (or restoring) the session.
  if (first.attach_case() == v1::ControlRequest::kSessionId) RouteToSession(&context_, first.session_id());
  stub_->async()->Control(&context_, this);
  // Writes start on the session's threads, outside gRPC's reactions: gRPC's contract for
  // that is a hold, without which the call may complete (and its stream object be freed)
  // between a check of done_ and a StartWrite. Removed once no operation will start.
  AddHold();
  {
    std::lock_guard<std::mutex> lock(mu_);
    waiting_ = first;
    PumpWritesLocked();
  }
  HandToGrpc(this);
  StartRead(&reading_);
  StartCall();
}

ControlCall::~ControlCall() {
  context_.TryCancel();
  ReleaseHold();
  std::unique_lock<std::mutex> lock(mu_);
  changed_.wait(lock, [this] { return done_; });
}

void ControlCall::ReleaseHold() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (ops_closed_) return;
    ops_closed_ = true;
  }
  HandToGrpc(this);
  RemoveHold();  // not under mu_: it may complete the call, and OnDone takes mu_
}

std::optional<std::uint64_t> ControlCall::Send(v1::ControlRequest request) {
  std::lock_guard<std::mutex> lock(mu_);
  std::optional<std::uint64_t> dropped;
  if (waiting_.has_value()) {
    dropped = waiting_->sequence();
    // The dropped request's report of held periods goes out with the one replacing it.
    request.set_held_periods(request.held_periods() + waiting_->held_periods());
  }
  waiting_ = std::move(request);
  PumpWritesLocked();
  return dropped;
}

void ControlCall::PumpWritesLocked() {
  if (write_in_flight_ || ops_closed_) return;
  if (waiting_.has_value()) {
    writing_ = *std::move(waiting_);
    waiting_.reset();
    write_in_flight_ = true;
    HandToGrpc(this);
    StartWrite(&writing_);
  } else if (writes_done_wanted_ && !writes_done_started_) {
    writes_done_started_ = true;
    write_in_flight_ = true;
    HandToGrpc(this);
    StartWritesDone();
    release_hold_ = true;  // nothing starts after the half-close: the caller releases the hold
  }
}

void ControlCall::OnWriteDone(bool ok) {
  TakeFromGrpc(this);
  bool release;
  {
    std::lock_guard<std::mutex> lock(mu_);
    write_in_flight_ = false;
    // A failed write means the call is ending; OnDone says how.
    if (ok) PumpWritesLocked();
    release = std::exchange(release_hold_, false);
  }
  if (release) ReleaseHold();
}

void ControlCall::OnWritesDoneDone(bool /*ok*/) {
  TakeFromGrpc(this);
  std::lock_guard<std::mutex> lock(mu_);
  write_in_flight_ = false;
}

void ControlCall::OnReadDone(bool ok) {
  TakeFromGrpc(this);
  if (!ok) {  // the stream is over: no more responses, no more writes; OnDone follows
    {
      std::lock_guard<std::mutex> lock(mu_);
      read_failed_ = true;
    }
    changed_.notify_all();
    ReleaseHold();
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    responses_.push_back(std::move(reading_));
    if (responses_.size() > kMaxUnreadResponses) responses_.pop_front();
  }
  changed_.notify_all();
  reading_.Clear();
  HandToGrpc(this);
  StartRead(&reading_);
}

void ControlCall::OnDone(const grpc::Status& status) {
  TakeFromGrpc(this);
  // Notified under the lock: the destructor, waiting for done_, may free this object as
  // soon as the lock is released.
  std::lock_guard<std::mutex> lock(mu_);
  status_ = status;
  done_ = true;
  changed_.notify_all();
}

absl::StatusOr<std::optional<v1::ControlResponse>> ControlCall::WaitFor(
    std::uint64_t sequence, Clock::time_point deadline, const std::function<void(const v1::ControlResponse&)>& other) {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    WaitUntil(lock, deadline, [this] { return !responses_.empty() || done_; });
    if (!responses_.empty()) {
      v1::ControlResponse response = std::move(responses_.front());
      responses_.pop_front();
      if (response.sequence() == sequence) return response;
      // Not under the lock: `other` may take its caller's locks, which are held around Send.
      lock.unlock();
      if (other) other(response);
      lock.lock();
      continue;
    }
    if (done_) return BrokenControlStreamStatus(status_);
    return std::nullopt;  // the deadline passed
  }
}

grpc::Status ControlCall::Finish(Clock::time_point deadline) {
  std::unique_lock<std::mutex> lock(mu_);
  writes_done_wanted_ = true;
  PumpWritesLocked();
  if (std::exchange(release_hold_, false)) {
    lock.unlock();
    ReleaseHold();
    lock.lock();
  }
  if (!WaitUntil(lock, deadline, [this] { return done_; })) {
    lock.unlock();
    Cancel();
    lock.lock();
    changed_.wait(lock, [this] { return done_; });
  }
  return status_;
}

void ControlCall::Cancel() {
  context_.TryCancel();
  ReleaseHold();
}

bool ControlCall::Ended() const {
  std::lock_guard<std::mutex> lock(mu_);
  return done_ || read_failed_;
}

}  // namespace nupmpc
