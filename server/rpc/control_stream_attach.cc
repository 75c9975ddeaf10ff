// ControlStream (server/rpc/control_stream.h): the first message, which attaches the stream
// to the session it names or creates.
#include "absl/strings/str_cat.h"
#include "server/observability/log_context.h"
#include "server/rpc/catch_exceptions.h"
#include "server/rpc/control_stream.h"
#include "server/sessions/session_factory.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {

absl::StatusOr<std::shared_ptr<SessionEntry>> ControlStream::Attach(const v1::ControlRequest& first) {
  std::shared_ptr<SessionEntry> entry;
  switch (first.attach_case()) {
    case v1::ControlRequest::kSessionId: {
      absl::StatusOr<std::shared_ptr<SessionEntry>> found =
          state_->FindOrRestore(first.session_id(), caller_, /*by_control_stream=*/true);
      if (!found.ok()) return found.status();
      entry = *std::move(found);
      // A stream-owned session is attached only by its stream, except one restored from a
      // snapshot: its stream ended with the server it lived on, and the reconnect of that
      // stream's client takes it over (and owns it: it closes when this stream ends).
      if ((entry->owned_by_stream && !entry->restored) || entry->attached.exchange(true)) {
        return absl::FailedPreconditionError(absl::StrCat("session_id ", QuoteSessionId(first.session_id()),
                                                          ": another Control stream is attached to it"));
      }
      break;
    }
    case v1::ControlRequest::kSpec: {
      CallContext call;  // the stream's deadline and cancellation bound a kernel fit on creation
      call.deadline = SteadyDeadline(*context_);
      call.cancel = &cancelled_;
      absl::StatusOr<std::shared_ptr<SessionEntry>> added =
          CreateAndRegister(first.spec(), state_->options.size_limits, &state_->gp_models, &state_->budget,
                            &state_->registry, call, /*owned_by_stream=*/true, /*requested_id=*/{}, OwnerFor(caller_),
                            /*keep_spec=*/state_->snapshots != nullptr);
      if (!added.ok()) return added.status();
      entry = *std::move(added);
      entry->attached.store(true);
      const LogContext log_context(entry->id, caller_.principal);
      spdlog::info("session {} created by a Control stream (M={}, L={}, K={}, N={})", entry->id,
                   entry->dims.num_states(), entry->dims.num_inputs(), entry->dims.num_outputs(),
                   entry->dims.horizon());
      break;
    }
    case v1::ControlRequest::ATTACH_NOT_SET:
      return absl::InvalidArgumentError("first ControlRequest: must carry session_id or spec (attach)");
  }
  return entry;
}

void ControlStream::StartAttach(v1::ControlRequest first) {
  // A registry lookup is fine in the reaction; building a session (from a spec, or from
  // its snapshot) goes to the pool.
  if (first.attach_case() == v1::ControlRequest::kSessionId && !state_->MayRestore(first.session_id(), caller_)) {
    AttachAndContinue(std::move(first));
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    flow_.Attaching();  // keeps the stream from finishing while the pool builds the session
  }
  const absl::Status queued = state_->pool.TrySubmit(
      [self = shared_from_this(), first = std::move(first)]() mutable { self->AttachAndContinue(std::move(first)); });
  if (queued.ok()) return;
  {
    std::lock_guard<std::mutex> lock(mu_);
    final_status_ = state_->ToGrpc(Rpc::kControl, queued);
    flow_.End();
  }
  Pump();
}

void ControlStream::AttachAndContinue(v1::ControlRequest first) {
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry;
  const absl::Status attached = RunCatchingExceptions("Control (first message)", [&] {
    entry = Attach(first);
    return entry.status();
  });
  if (!attached.ok()) entry = attached;
  bool read_more = false;
  std::optional<v1::ControlRequest> start;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!entry.ok()) {
      final_status_ = state_->ToGrpc(Rpc::kControl, entry.status());
      // An attach by id that found no session is also answered (before the status): a
      // balancer may turn the end of a stream the client has not half-closed into a bare
      // RST_STREAM(CANCEL) (HAProxy 2.6 does), and a client reconnecting by id must still
      // learn that it has to re-create its session.
      if (first.attach_case() == v1::ControlRequest::kSessionId &&
          (absl::IsNotFound(entry.status()) || absl::IsFailedPrecondition(entry.status()))) {
        QueueWriteLocked(ErrorResponse(first.sequence(), final_status_));
      }
      flow_.End();
    } else {
      entry_ = *std::move(entry);
      flow_.Opened();
      if (first.has_step()) {
        start = EnqueueStepLocked(std::move(first));
      } else {
        v1::ControlResponse hello;
        hello.set_sequence(first.sequence());
        hello.set_session_id(entry_->id);
        QueueWriteLocked(hello);
      }
      read_more = ShouldReadLocked();
      if (read_more) flow_.ReadDecided();
    }
  }
  if (read_more) ReadNext();
  if (start.has_value()) StartSolve(*std::move(start), /*read_after_solve=*/false);
  Pump();
}

}  // namespace nupmpc::server
