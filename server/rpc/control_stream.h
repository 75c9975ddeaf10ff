#ifndef NUPMPC_SERVER_RPC_CONTROL_STREAM_H_
#define NUPMPC_SERVER_RPC_CONTROL_STREAM_H_

#include <atomic>
#include <memory>
#include <mutex>
#include <optional>

#include "grpcpp/alarm.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"
#include "server/auth/caller.h"
#include "server/rpc/read_timing.h"
#include "server/rpc/stream_flow.h"
#include "server/state/server_state.h"

namespace nupmpc::server {

// One Control stream (the main path). The first message attaches to a session or creates
// one owned by the stream; every message with a step is answered once, in order. The
// reactor's plumbing is control_stream.cc, the first message control_stream_attach.cc, a
// step's way from parking to its answer control_stream_solve.cc.
//
// Flow control (server/rpc/stream_flow.h, this reactor carries out its decisions with
// gRPC's calls), "newest state wins": at most one step of a stream is being solved and at
// most one waits. A step that arrives while another one waits replaces it, and the replaced
// one is answered at once with SOLVE_STATUS_SUPERSEDED (nothing of it is applied). A client
// that sends faster than the server solves therefore always gets the plan for its latest
// state next, and never builds up a backlog. A step solved in place is read ahead of only
// while the client shows it sends before its answers (server/rpc/read_timing.h): a closed
// loop's next step is read after the solve, which is cheaper and loses nothing.
//
// Bounded: at most ServerLimits.max_stream_answers answers wait for the client to read
// them; then the stream stops reading (HTTP/2 flow control holds the client's writes) until
// it does. At most max_control_streams streams are open server-wide. A stream whose first
// message has not arrived within first_message_timeout_s is ended with DEADLINE_EXCEEDED,
// so silent streams cannot hold those slots.
//
// Messages are parsed here from raw bytes: a first message that does not parse ends the
// stream with INVALID_ARGUMENT, a later one is answered with error_code 3 (sequence 0).
//
// A bad step is answered with error_code/error_message and the stream stays open (the
// session is unchanged); a bad first message ends the stream with that status.
//
// Lifetime: gRPC and every task on the worker pool each hold a reference. gRPC calls
// OnDone (and drops its reference) once Finish has completed, which can happen on a
// gRPC thread while a worker is still running the tail of its task after it handed back
// the stream (answer queued, the solve ended in flow_, lock released); the last reference to
// go deletes the stream.
class ControlStream : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>,
                      public std::enable_shared_from_this<ControlStream> {
 public:
  // The reactor for one Control call; it owns itself (see Lifetime above).
  static ControlStream* Start(ServerState* state, grpc::CallbackServerContext* context);

  void OnReadDone(bool ok) override;
  void OnWriteDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

 private:
  ControlStream(ServerState* state, grpc::CallbackServerContext* context);
  // Starts reading (and the first message's timer), or refuses the call while the server drains.
  void Begin();
  // The first message's timer fired (`fired`: not cancelled): ends a stream still waiting for it.
  void OnFirstMessageTimeout(bool fired);
  // Ends the stream with UNAUTHENTICATED: its caller's token was revoked (the janitor, once
  // a second, through ServerState::principal_streams). What is being solved is answered
  // first; a parked step is dropped.
  void Revoke();
  // The session the first message names or creates (marked attached).
  absl::StatusOr<std::shared_ptr<SessionEntry>> Attach(const v1::ControlRequest& first);
  // Handles the first message: on the pool when it carries a spec (building a session
  // converts and allocates, which can take long for big problems), else in the reaction.
  void StartAttach(v1::ControlRequest first);
  // Attaches (or ends the stream with the reason it could not), answers or solves the
  // first message, and resumes reading.
  void AttachAndContinue(v1::ControlRequest first);
  // Accepts a step: parks it (superseding the parked one) and returns the step to start now
  // if none is being solved (the caller passes it to StartSolve once it has let go of mu_).
  std::optional<v1::ControlRequest> EnqueueStepLocked(v1::ControlRequest request);
  // The parked step, marked as being solved (and counted in ServerState::work_in_flight),
  // if none is. Called with mu_.
  std::optional<v1::ControlRequest> TakeParkedLocked();
  // The step being solved was answered: no longer counted in ServerState::work_in_flight.
  void SolveEndedLocked();
  // Whether a step due at `due` (StepDue; none: no deadline) is solved on the thread that
  // has it (server/scheduling/solve_in_place.h), and whether it is short (a core-holding
  // thread may take it from the queue). Reads only atomics: callable with or without mu_.
  struct WhereToSolve {
    bool in_place = false;
    bool short_solve = false;
  };
  WhereToSolve PlaceStep(std::optional<Clock::time_point> due) const;
  // Solves a step taken by TakeParkedLocked: here if the session and a core are free and
  // PlaceStep says so (no hand-off to a worker: the latency of a transport-bound step, or of
  // a step the hand-off would make late), else on the pool through the session's strand. Called without mu_; the caller
  // Pumps afterwards (an answer solved in place is written then). `read_after_solve`: the next read was held back for
  // this step (ReadTiming): it starts once the answer is written if the step is solved here, else at once, ahead of the
  // solve on the pool.
  void StartSolve(v1::ControlRequest request, bool read_after_solve);
  // Starts the read StartSolve held back, unless the stream stopped reading meanwhile.
  void ReadHeldBack();
  // Solves and queues the answer; `pump`: also starts writing it (on a worker; in place the
  // caller of StartSolve does, after the core is given back).
  void Solve(v1::ControlRequest request, Clock::time_point queued_at, bool pump);
  // The strand could not hand a queued solve to the pool (full, shutting down): answer it.
  void FailQueuedSolve(std::uint64_t sequence, const absl::Status& refused);
  // The answer to a message that failed with `status` (error_code, error_message).
  static v1::ControlResponse ErrorResponse(std::uint64_t sequence, const grpc::Status& status);
  void QueueWriteLocked(const v1::ControlResponse& response);
  // Whether to start the next read now: not while the client leaves max_stream_answers
  // answers unread (StreamFlow::ShouldRead; counts the pauses). Called with mu_; a caller
  // that then reads calls flow_.ReadDecided() before it lets go of mu_.
  bool ShouldReadLocked();
  // Starts the next write / finishes the stream if nothing is left. Called without mu_.
  void Pump();
  // gRPC's StartRead / StartWrite / Finish, each announced to ThreadSanitizer as a hand-over
  // to gRPC's threads (server/rpc/grpc_handover.h).
  // `after_solve`: the read starts after the solve of the step read before it (ReadTiming).
  // The caller counted it (flow_.ReadDecided()).
  void ReadNext(bool after_solve = false);
  void Write(const grpc::ByteBuffer* bytes);
  void End(const grpc::Status& status);
  // Closes the session this stream created, once: before the stream's status when it ends
  // by itself (so that a client holding the status no longer sees or counts the session),
  // else in OnDone. Called without mu_; ordered before OnDone by End's hand-over.
  void CloseOwnedSession();
  // Why the stream ended (for OnDone's metric and log line).
  StreamEnd EndCause();
  // Counts and logs the periods the client says it held (ControlRequest.held_periods).
  void NoteHeldPeriods(std::uint32_t periods);

  ServerState* const state_;
  // Valid until OnDone; read only while the stream cannot finish (a read pending, the
  // phase kAttaching or a step being solved).
  grpc::CallbackServerContext* const context_;
  std::shared_ptr<ControlStream> grpc_reference_;  // set by Start, dropped by OnDone
  grpc::ByteBuffer read_buffer_;                   // raw: parsed by OnReadDone (server/rpc/raw_messages.h)
  std::atomic<bool> cancelled_{false};
  bool counted_ = false;  // in state_->control_streams (set by Begin, before any reaction)
  const Caller caller_;   // who opened the stream: owns the session it creates
  const Clock::time_point started_at_ = Clock::now();
  bool counted_for_principal_ = false;  // in state_->principal_streams (set by Begin)
  bool owned_session_closed_ = false;   // by CloseOwnedSession

  using Flow = StreamFlow<v1::ControlRequest, grpc::ByteBuffer>;

  std::mutex mu_;
  // The phase, reads, parked and solved step, and queued answers; kEnding ends the stream
  // with Finish(final_status_).
  Flow flow_;
  std::shared_ptr<SessionEntry> entry_;  // set by the first message
  // What handing an answer to gRPC takes (from the end of its solve to OnWriteDone, for
  // answers written at once), exponentially weighted: kept free of a step's deadline.
  std::atomic<double> send_cost_ms_{0.05};
  std::optional<Clock::time_point> timed_write_since_;  // the answer being timed, if any
  std::uint64_t held_not_logged_ = 0;                   // periods the client reported, not yet logged
  Clock::time_point held_logged_at_{};                  // the last such log line
  ReadTiming read_timing_;
  bool read_after_solve_ = false;                    // the pending read was started after a solve
  Clock::time_point read_started_at_;                // when the pending read was started
  Clock::time_point last_message_at_ = started_at_;  // when the client's latest message arrived
  grpc::Status final_status_;
  // Set by Begin; cancelled once the first message arrives (the callback holds only a weak
  // reference, so a pending timer never keeps the stream alive).
  grpc::Alarm first_message_timer_;
  bool done_ = false;  // OnDone ran: context_ is gone
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_CONTROL_STREAM_H_
