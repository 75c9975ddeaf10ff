#include "client/control_call.h"

#include <utility>

#include "absl/strings/str_cat.h"

namespace nupmpc {

absl::Status BrokenControlStreamStatus(const grpc::Status& s) {
  if (s.ok()) return absl::UnavailableError("the Control stream ended");
  // A session never cancels a live stream and still waits on it: CANCELLED here is the
  // server dropping the call (e.g. shutting down past its grace period) or gRPC ending it
  // for a connection that died (keepalive), as retryable as a lost connection.
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
  stub_->async()->Control(&context_, this);
  {
    std::lock_guard<std::mutex> lock(mu_);
    waiting_ = first;
    PumpWritesLocked();
  }
  StartRead(&reading_);
  StartCall();
}

ControlCall::~ControlCall() {
  context_.TryCancel();
  std::unique_lock<std::mutex> lock(mu_);
  changed_.wait(lock, [this] { return done_; });
}

std::optional<std::uint64_t> ControlCall::Send(const v1::ControlRequest& request) {
  std::lock_guard<std::mutex> lock(mu_);
  std::optional<std::uint64_t> dropped;
  if (waiting_.has_value()) dropped = waiting_->sequence();
  waiting_ = request;
  PumpWritesLocked();
  return dropped;
}

void ControlCall::PumpWritesLocked() {
  if (write_in_flight_ || done_) return;
  if (waiting_.has_value()) {
    writing_ = *std::move(waiting_);
    waiting_.reset();
    write_in_flight_ = true;
    StartWrite(&writing_);
  } else if (writes_done_wanted_ && !writes_done_started_) {
    writes_done_started_ = true;
    write_in_flight_ = true;
    StartWritesDone();
  }
}

void ControlCall::OnWriteDone(bool ok) {
  std::lock_guard<std::mutex> lock(mu_);
  write_in_flight_ = false;
  // A failed write means the call is ending; OnDone says how.
  if (ok) PumpWritesLocked();
}

void ControlCall::OnWritesDoneDone(bool /*ok*/) {
  std::lock_guard<std::mutex> lock(mu_);
  write_in_flight_ = false;
}

void ControlCall::OnReadDone(bool ok) {
  if (!ok) return;  // no more responses; OnDone follows
  {
    std::lock_guard<std::mutex> lock(mu_);
    responses_.push_back(std::move(reading_));
    if (responses_.size() > kMaxUnreadResponses) responses_.pop_front();
  }
  changed_.notify_all();
  reading_.Clear();
  StartRead(&reading_);
}

void ControlCall::OnDone(const grpc::Status& status) {
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
  if (!WaitUntil(lock, deadline, [this] { return done_; })) {
    context_.TryCancel();
    changed_.wait(lock, [this] { return done_; });
  }
  return status_;
}

void ControlCall::Cancel() { context_.TryCancel(); }

bool ControlCall::Ended() const {
  std::lock_guard<std::mutex> lock(mu_);
  return done_;
}

}  // namespace nupmpc
