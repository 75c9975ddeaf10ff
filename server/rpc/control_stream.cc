#include "server/rpc/control_stream.h"

#include "absl/strings/str_cat.h"
#include "nupmpc/grpc_handover.h"
#include "server/observability/log_context.h"
#include "server/rpc/raw_messages.h"
#include "server/sessions/step_deadline.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {
namespace {

// The hand-over address of the first-message alarms' callbacks (server/rpc/grpc_handover.h).
const char kFirstMessageAlarms = 0;

}  // namespace

v1::ControlResponse ControlStream::ErrorResponse(std::uint64_t sequence, const grpc::Status& status) {
  v1::ControlResponse r;
  r.set_sequence(sequence);
  r.set_error_code(status.error_code());
  r.set_error_message(status.error_message());
  return r;
}

ControlStream* ControlStream::Start(ServerState* state, grpc::CallbackServerContext* context) {
  // std::make_shared cannot reach the private constructor.
  std::shared_ptr<ControlStream> stream(new ControlStream(state, context));
  stream->grpc_reference_ = stream;
  stream->Begin();
  return stream.get();
}

ControlStream::ControlStream(ServerState* state, grpc::CallbackServerContext* context)
    : state_(state), context_(context), caller_(CallerOf(*context, state->auth.get())) {}

void ControlStream::Begin() {
  if (state_->draining.load()) {
    End(state_->ToGrpc(Rpc::kControl, absl::UnavailableError("the server is shutting down")));
    return;
  }
  counted_ = true;
  if (state_->control_streams.fetch_add(1) >= state_->options.max_control_streams) {
    End(state_->ToGrpc(Rpc::kControl,
                       absl::ResourceExhaustedError(absl::StrCat(
                           "the server has its maximum of ", state_->options.max_control_streams,
                           " Control streams open (ServerLimits.max_control_streams); close one or retry later"))));
    return;
  }
  std::function<void()> revoke;
  if (caller_.by_token) {
    revoke = [weak = weak_from_this()] {
      if (const std::shared_ptr<ControlStream> self = weak.lock()) self->Revoke();
    };
  }
  if (absl::Status quota = state_->principal_streams.Acquire(caller_.principal, this, std::move(revoke)); !quota.ok()) {
    End(state_->ToGrpc(Rpc::kControl, quota));
    return;
  }
  counted_for_principal_ = true;
  const auto timeout = std::chrono::duration_cast<std::chrono::system_clock::duration>(
      std::chrono::duration<double>(state_->options.first_message_timeout_s));
  // The callback runs on one of gRPC's threads, after Set. For TSan: handed over through one
  // address for all streams, as the callback cannot read its captures before it has taken
  // them over (and the stream may be gone).
  first_message_timer_.Set(std::chrono::system_clock::now() + timeout, [weak = weak_from_this()](bool fired) {
    TakeFromGrpc(&kFirstMessageAlarms);
    if (const std::shared_ptr<ControlStream> self = weak.lock()) self->OnFirstMessageTimeout(fired);
  });
  HandToGrpc(&kFirstMessageAlarms);
  {
    std::lock_guard<std::mutex> lock(mu_);
    flow_.ReadDecided();
  }
  ReadNext();
}

void ControlStream::OnFirstMessageTimeout(bool fired) {
  if (!fired) return;
  {
    std::lock_guard<std::mutex> lock(mu_);
    // Through Pump, which finishes only once Begin's read has been started (ReadStarted):
    // the timer can fire before it is. The pending read then completes with !ok, or with a
    // late first message that OnReadDone drops.
    if (done_ || !flow_.EndWithoutFirstMessage()) return;
    final_status_ = state_->ToGrpc(
        Rpc::kControl,
        absl::DeadlineExceededError(absl::StrCat(
            "first ControlRequest: none within first_message_timeout_s = ", state_->options.first_message_timeout_s,
            " s (ServerLimits.first_message_timeout_s); send the attach at once")));
  }
  Pump();
}

void ControlStream::Revoke() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    // While the first message's session is built (kAttaching) the phase is not ours to
    // change: the janitor revokes again a second later. A parked step is dropped: nothing
    // more is solved for a caller whose access is gone.
    if (done_ || !flow_.Revoke()) return;
    final_status_ = state_->ToGrpc(
        Rpc::kControl, absl::UnauthenticatedError(absl::StrCat("principal \"", caller_.principal,
                                                               "\": its token was removed from the server's tokens "
                                                               "file; the stream ends")));
  }
  Pump();
}

bool ControlStream::ShouldReadLocked() {
  // The client does not read its answers: stop reading its steps (flow control) until it does.
  bool paused_now = false;
  const bool read = flow_.ShouldRead(state_->options.max_stream_answers, &paused_now);
  if (paused_now) state_->stream_read_pauses.fetch_add(1, std::memory_order_relaxed);
  return read;
}

void ControlStream::OnReadDone(bool ok) {
  TakeFromGrpc(this);
  if (!ok) {  // the client half-closed (or went away)
    {
      std::lock_guard<std::mutex> lock(mu_);
      flow_.ReadingDone();
    }
    Pump();
    return;
  }
  v1::ControlRequest request;
  const absl::Status parsed = ParseRaw(&read_buffer_, &request);
  read_buffer_.Clear();
  // The next read starts only once the first message is handled. Taking the first message
  // moves the phase on under the lock, so the first-message timer cannot end the stream
  // while it is handled (and a message that arrives after the timer ended it is dropped).
  bool first_message;
  {
    std::lock_guard<std::mutex> lock(mu_);
    last_message_at_ = Clock::now();
    // Ending before its first message was handled (its timer fired): drop what arrives.
    const Flow::Arrival arrival = flow_.MessageArrived();
    if (arrival == Flow::Arrival::kDropped) return;
    first_message = arrival == Flow::Arrival::kFirst;
  }
  if (parsed.ok() && request.held_periods() > 0) NoteHeldPeriods(request.held_periods());
  if (first_message) first_message_timer_.Cancel();
  if (first_message && !parsed.ok()) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      final_status_ = state_->ToGrpc(Rpc::kControl, parsed);
      flow_.End();
    }
    Pump();
    return;
  }
  if (first_message) {
    StartAttach(std::move(request));
    return;
  }
  bool read_more;
  bool read_ahead = true;
  bool read_after_solve = false;
  std::optional<v1::ControlRequest> start;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!parsed.ok()) {
      QueueWriteLocked(ErrorResponse(0, state_->ToGrpc(Rpc::kControl, parsed)));
    } else if (request.attach_case() != v1::ControlRequest::ATTACH_NOT_SET) {
      QueueWriteLocked(ErrorResponse(
          request.sequence(),
          state_->ToGrpc(Rpc::kControl,
                         absl::InvalidArgumentError("attach: only the first ControlRequest may carry it"))));
    } else if (!request.has_step()) {
      QueueWriteLocked(ErrorResponse(
          request.sequence(),
          state_->ToGrpc(Rpc::kControl, absl::InvalidArgumentError("step: required after the first message"))));
    } else {
      read_timing_.StepArrived(flow_.solving(), read_after_solve_, Clock::now() - read_started_at_, flow_.writing());
      start = EnqueueStepLocked(std::move(request));
      read_ahead = read_timing_.ReadAhead();
    }
    read_more = ShouldReadLocked();
    // Reading on first: a newer step that arrives during the solve supersedes the parked
    // one; unless the client waits for its answers and the step is solved here (ReadTiming).
    read_after_solve = read_more && start.has_value() && !read_ahead &&
                       PlaceStep(StepDue(entry_->timing, start->step(), flow_.solving_received_at())).in_place;
    if (read_more && !read_after_solve) flow_.ReadDecided();
  }
  if (read_more && !read_after_solve) ReadNext();
  if (start.has_value()) StartSolve(*std::move(start), read_after_solve);
  Pump();
}

void ControlStream::QueueWriteLocked(const v1::ControlResponse& response) {
  grpc::ByteBuffer bytes;
  if (!SerializeRaw(response, &bytes).ok()) {  // cannot happen for a message we built; never send nothing
    (void)SerializeRaw(ErrorResponse(response.sequence(), grpc::Status(grpc::StatusCode::INTERNAL, "unserializable")),
                       &bytes);
  }
  flow_.QueueAnswer(bytes);
}

void ControlStream::Pump() {
  const grpc::ByteBuffer* to_write = nullptr;
  bool finish = false;
  bool close_owned_session = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    finish = flow_.Pump(&to_write) == Flow::Next::kFinish;
    // No solve of it runs: the flow finishes only when none is being solved.
    close_owned_session = finish && entry_ != nullptr && entry_->owned_by_stream;
  }
  if (to_write != nullptr) Write(to_write);
  if (close_owned_session) CloseOwnedSession();
  if (finish) End(final_status_);
}

void ControlStream::CloseOwnedSession() {
  if (owned_session_closed_) return;
  owned_session_closed_ = true;
  const LogContext log_context(entry_->id, caller_.principal);
  (void)state_->registry.Close(entry_->id);
  spdlog::info("session {} closed with its Control stream", entry_->id);
}

void ControlStream::ReadNext(bool after_solve) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    read_after_solve_ = after_solve;
    read_started_at_ = Clock::now();
  }
  HandToGrpc(this);
  StartRead(&read_buffer_);
  // From here the pending read keeps the stream open (its OnReadDone pumps), but a stream
  // that is ending finishes without waiting for the client: the Finish Pump held back.
  bool pump;
  {
    std::lock_guard<std::mutex> lock(mu_);
    pump = flow_.ReadStarted();
  }
  if (pump) Pump();
}

void ControlStream::Write(const grpc::ByteBuffer* bytes) {
  HandToGrpc(this);
  StartWrite(bytes);
}

void ControlStream::End(const grpc::Status& status) {
  HandToGrpc(this);
  Finish(status);
}

void ControlStream::OnWriteDone(bool ok) {
  TakeFromGrpc(this);
  bool resume_reading = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (timed_write_since_.has_value()) {
      const double took_ms = std::chrono::duration<double, std::milli>(Clock::now() - *timed_write_since_).count();
      const double cost_ms = send_cost_ms_.load(std::memory_order_relaxed);
      send_cost_ms_.store(0.8 * cost_ms + 0.2 * took_ms, std::memory_order_relaxed);
      timed_write_since_.reset();
    }
    // !ok: the client is gone; what is left is dropped.
    resume_reading = flow_.WriteDone(ok, state_->options.max_stream_answers);
    if (resume_reading) flow_.ReadDecided();
  }
  if (resume_reading) ReadNext();
  Pump();
}

void ControlStream::OnCancel() {
  TakeFromGrpc(this);
  cancelled_.store(true);
}

void ControlStream::NoteHeldPeriods(std::uint32_t periods) {
  state_->client_held_periods.fetch_add(periods);
  std::shared_ptr<SessionEntry> entry;
  std::uint64_t to_log = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    entry = entry_;
    // One line a second at most: a client that misses every other period would otherwise
    // write one per step.
    held_not_logged_ += periods;
    const Clock::time_point now = Clock::now();
    if (now - held_logged_at_ >= std::chrono::seconds(1)) {
      to_log = std::exchange(held_not_logged_, 0);
      held_logged_at_ = now;
    }
  }
  if (to_log == 0) return;
  const LogContext log_context(entry != nullptr ? absl::string_view(entry->id) : absl::string_view(),
                               caller_.principal);
  spdlog::info("session {}: its client held {} control periods without an answer in time",
               entry != nullptr ? entry->id : std::string("(attaching)"), to_log);
}

StreamEnd ControlStream::EndCause() {
  if (!cancelled_.load()) return final_status_.ok() ? StreamEnd::kClientClosed : StreamEnd::kServerEnded;
  // A shutdown cancels the streams it did not let finish.
  if (state_->draining.load()) return StreamEnd::kServerEnded;
  // gRPC does not say why a call was cancelled. A client that had been silent for longer
  // than the keepalive timeout before it did is one the keepalive pings found gone (a
  // partition, a frozen client); a cancellation that follows traffic is the client's own
  // (or its connection was reset).
  std::lock_guard<std::mutex> lock(mu_);
  const double silent_s = std::chrono::duration<double>(Clock::now() - last_message_at_).count();
  return silent_s >= state_->options.keepalive_timeout_s ? StreamEnd::kKeepalive : StreamEnd::kClientGone;
}

void ControlStream::OnDone() {
  TakeFromGrpc(this);
  // Deletes this stream on return unless a pool task still holds it.
  const std::shared_ptr<ControlStream> last_reference_maybe = std::move(grpc_reference_);
  {
    std::lock_guard<std::mutex> lock(mu_);
    done_ = true;
  }
  first_message_timer_.Cancel();
  if (counted_) state_->control_streams.fetch_sub(1);
  if (counted_for_principal_) state_->principal_streams.Release(caller_.principal, this);
  const LogContext log_context(entry_ != nullptr ? absl::string_view(entry_->id) : absl::string_view(),
                               caller_.principal);
  const StreamEnd cause = EndCause();
  state_->stream_ends.Record(cause);
  if (spdlog::should_log(spdlog::level::debug)) {
    spdlog::debug("access: Control ended after {:.3f} s peer {} ({})",
                  std::chrono::duration<double>(Clock::now() - started_at_).count(), caller_.connection,
                  StreamEndName(cause));
  }
  if (entry_ != nullptr && cause != StreamEnd::kClientClosed) {
    spdlog::info("session {}: its Control stream ended: {}", entry_->id, StreamEndName(cause));
  }
  if (entry_ != nullptr) {
    if (entry_->owned_by_stream) {
      CloseOwnedSession();  // unless the stream's end did, before its status
    } else {
      entry_->attached.store(false);
      spdlog::info("session {}: its Control stream detached", entry_->id);
    }
  }
  HandToGrpc(state_);  // before grpc::Server::Shutdown returns (GrpcServer::Shutdown)
}

}  // namespace nupmpc::server
