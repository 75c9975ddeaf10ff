// ControlStream (server/rpc/control_stream.h): a step from parking to its answer: which step
// is solved next, where (on the thread that has it or on the pool), and the solve itself.
#include "server/rpc/catch_exceptions.h"
#include "server/rpc/control_stream.h"
#include "server/scheduling/solve_in_place.h"
#include "server/sessions/step_deadline.h"
#include "server/sessions/step_solver.h"

namespace nupmpc::server {

std::optional<v1::ControlRequest> ControlStream::EnqueueStepLocked(v1::ControlRequest request) {
  if (state_->draining.load()) {
    // With a state directory the step is not answered: the stream ends once its session's
    // snapshot is written (GrpcServer::Shutdown), and the client resends the step to the
    // replica that restores the session. Answered now, the client would ask for its session
    // before the snapshot exists, and re-create it cold.
    if (state_->snapshots == nullptr) {
      QueueWriteLocked(ErrorResponse(
          request.sequence(), state_->ToGrpc(Rpc::kControl, absl::UnavailableError("the server is shutting down"))));
    }
    return std::nullopt;
  }
  if (const std::optional<v1::ControlRequest> replaced = flow_.Park(std::move(request), Clock::now())) {
    v1::ControlResponse superseded;
    superseded.set_sequence(replaced->sequence());
    superseded.mutable_result()->set_status(v1::SOLVE_STATUS_SUPERSEDED);
    QueueWriteLocked(superseded);
  }
  return TakeParkedLocked();
}

std::optional<v1::ControlRequest> ControlStream::TakeParkedLocked() {
  std::optional<v1::ControlRequest> step = flow_.TakeParked();
  if (step.has_value()) state_->work_in_flight.fetch_add(1);
  return step;
}

void ControlStream::SolveEndedLocked() {
  if (flow_.solving()) state_->work_in_flight.fetch_add(-1);
  flow_.SolveEnded();
}

ControlStream::WhereToSolve ControlStream::PlaceStep(std::optional<Clock::time_point> due) const {
  InPlaceInputs in;
  in.expected_cpu_ms = entry_->last_solve_cpu_ms.load(std::memory_order_relaxed);
  in.inline_max_ms = state_->options.inline_solve_max_ms;
  in.handoff_ms = state_->pool.handoff_ms();
  if (due.has_value()) {
    in.left_ms = std::chrono::duration<double, std::milli>(*due - Clock::now()).count() -
                 send_cost_ms_.load(std::memory_order_relaxed);
  }
  return {.in_place = SolvesInPlace(in), .short_solve = IsShortSolve(in)};
}

void ControlStream::StartSolve(v1::ControlRequest request, bool read_after_solve) {
  for (;;) {
    const std::uint64_t sequence = request.sequence();
    const auto queued_at = Clock::now();
    // Through the session's strand either way: a unary Solve accepted just before this
    // stream attached runs first, without a worker waiting for it.
    // In place, the answer is written once the session is given back: the client's next
    // step, sent as soon as it has the answer, then finds the session free. This thread
    // keeps the core for up to inline_solve_max_ms more of short steps that arrived
    // meanwhile (other streams', and this one's next), as a worker would, but without
    // handing each to another thread.
    Clock::time_point received_at;
    {
      std::lock_guard<std::mutex> lock(mu_);
      received_at = flow_.solving_received_at();
    }
    const std::optional<Clock::time_point> due = StepDue(entry_->timing, request.step(), received_at);
    const WhereToSolve placement = PlaceStep(due);
    if (placement.in_place &&
        SessionStrand::TryRunHere(
            entry_->strand, state_->pool, [&] { Solve(std::move(request), queued_at, /*pump=*/false); },
            [this, read_after_solve] {
              Pump();  // the answer first: the read must not start before it left
              if (read_after_solve) ReadHeldBack();
            },
            state_->options.inline_solve_max_ms)) {
      return;
    }
    if (read_after_solve) {  // not solved here after all: read ahead of the solve on the pool
      read_after_solve = false;
      ReadHeldBack();
    }
    const absl::Status queued = SessionStrand::Submit(
        entry_->strand, state_->pool,
        {[self = shared_from_this(), request = std::move(request), queued_at]() mutable {
           self->Solve(std::move(request), queued_at, /*pump=*/true);
         },
         [self = shared_from_this(), sequence](const absl::Status& refused) {
           self->FailQueuedSolve(sequence, refused);
         },
         entry_->last_solve_ms.load(std::memory_order_relaxed),
         placement.short_solve ? WorkerPool::Placement::kAnyCoreHolder : WorkerPool::Placement::kWorker, due});
    if (queued.ok()) return;
    std::optional<v1::ControlRequest> next;
    {
      std::lock_guard<std::mutex> lock(mu_);
      QueueWriteLocked(ErrorResponse(sequence, state_->ToGrpc(Rpc::kControl, queued)));
      SolveEndedLocked();
      next = TakeParkedLocked();  // parked while this one was being handed over
    }
    if (!next.has_value()) return;
    request = *std::move(next);
  }
}

void ControlStream::ReadHeldBack() {
  bool read_more;
  {
    std::lock_guard<std::mutex> lock(mu_);
    read_more = ShouldReadLocked();
    if (read_more) flow_.ReadDecided();
  }
  if (read_more) {
    ReadNext(/*after_solve=*/true);
  } else {
    Pump();  // the read the stream waited for will not come: it may finish now
  }
}

void ControlStream::FailQueuedSolve(std::uint64_t sequence, const absl::Status& refused) {
  std::optional<v1::ControlRequest> next;
  {
    std::lock_guard<std::mutex> lock(mu_);
    QueueWriteLocked(ErrorResponse(sequence, state_->ToGrpc(Rpc::kControl, refused)));
    SolveEndedLocked();
    next = TakeParkedLocked();
  }
  if (next.has_value()) StartSolve(*std::move(next), /*read_after_solve=*/false);
  Pump();
}

void ControlStream::Solve(v1::ControlRequest request, Clock::time_point queued_at, bool pump) {
  const auto started_at = Clock::now();
  CallContext call;
  call.deadline = SteadyDeadline(*context_);
  call.cancel = &cancelled_;
  {
    std::lock_guard<std::mutex> lock(mu_);
    call.received_at = flow_.solving_received_at();
  }
  call.send_cost_ms = send_cost_ms_.load(std::memory_order_relaxed);
  v1::ControlResponse response;
  response.set_sequence(request.sequence());
  const absl::Status status = RunCatchingExceptions(
      "Control", [&] { return SolveStep(*entry_, request.step(), call, response.mutable_result()); });
  if (status.ok()) {
    state_->RecordSolve(response.result(), entry_.get(), std::chrono::duration<double>(started_at - queued_at).count(),
                        std::chrono::duration<double>(Clock::now() - queued_at).count());
  }
  std::optional<v1::ControlRequest> next;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (status.ok()) {
      if (flow_.answers_idle()) timed_write_since_ = Clock::now();  // written at once: a clean sample
      QueueWriteLocked(response);
    } else {
      QueueWriteLocked(ErrorResponse(request.sequence(), state_->ToGrpc(Rpc::kControl, status)));
    }
    SolveEndedLocked();
    next = TakeParkedLocked();
  }
  // Still inside this session's strand task: the next step queues behind it.
  if (next.has_value()) StartSolve(*std::move(next), /*read_after_solve=*/false);
  if (pump) Pump();
}

}  // namespace nupmpc::server
