#ifndef NUPMPC_SERVER_RPC_STREAM_FLOW_H_
#define NUPMPC_SERVER_RPC_STREAM_FLOW_H_

#include <chrono>
#include <deque>
#include <optional>
#include <utility>

namespace nupmpc::server {

// The flow control of one Control stream (server/rpc/control_stream.h), without gRPC: where
// the stream is in its life, whether it reads, the step that waits ("newest state wins"),
// whether one is being solved, and the answers that wait to be written. The reactor asks
// it what to do next and carries that out with gRPC's calls; it holds its own lock around
// every call (this class has none).
//
// `Step` is a parsed request, `Answer` a serialized answer; the front answer stays at its
// address while it is written (a deque: later answers are added at the back).
template <typename Step, typename Answer>
class StreamFlow {
 public:
  using Clock = std::chrono::steady_clock;

  // Where the stream is in its life.
  enum class Phase {
    kAwaitingFirst,  // the first message is being read (or looked up, in the reaction)
    kAttaching,      // the first message's session is being built on the pool
    kOpen,           // attached: steps are read, solved and answered
    kEnding,         // no more work: queued answers are written, then the stream finishes
    kFinished,       // the stream was told to finish
  };
  // Whether a read is pending.
  enum class Reading {
    kActive,  // a read is pending (or starts as soon as the current message is handled)
    kPaused,  // max_answers answers wait for the client: WriteDone resumes
    kDone,    // the client half-closed or went away
  };
  // What a message that arrived is, by the phase it arrived in.
  enum class Arrival {
    kDropped,  // the stream is ending (its first message's timer fired): nothing of it is used
    kFirst,    // the first message: the phase is now kAttaching, the timer may no longer end it
    kStep,     // a later message
  };

  Phase phase() const { return phase_; }
  bool solving() const { return solving_; }
  bool writing() const { return writing_; }
  // Whether an answer queued now is written at once (none is being written or waits).
  bool answers_idle() const { return !writing_ && writes_.empty(); }
  // When the step being solved arrived (its deadline counts from it).
  Clock::time_point solving_received_at() const { return solving_received_at_; }

  // A message arrived (see Arrival).
  Arrival MessageArrived() {
    if (phase_ == Phase::kFinished || phase_ == Phase::kEnding) return Arrival::kDropped;
    if (phase_ != Phase::kAwaitingFirst) return Arrival::kStep;
    phase_ = Phase::kAttaching;
    return Arrival::kFirst;
  }
  // The first message's session is being built elsewhere: the stream may not finish.
  void Attaching() { phase_ = Phase::kAttaching; }
  // The first message attached the stream to its session.
  void Opened() { phase_ = Phase::kOpen; }
  // No more work: the queued answers are written, then the stream finishes.
  void End() { phase_ = Phase::kEnding; }
  // The first message's timer fired: ends a stream still waiting for it (true if it did).
  bool EndWithoutFirstMessage() {
    if (phase_ != Phase::kAwaitingFirst) return false;
    phase_ = Phase::kEnding;
    return true;
  }
  // The caller's access is gone: ends the stream, dropping a parked step (true if it did).
  // What is being solved is still answered. Not while the first message's session is being
  // built (the phase is then not the caller's to change) or once ending.
  bool Revoke() {
    if (phase_ == Phase::kAttaching || phase_ == Phase::kEnding || phase_ == Phase::kFinished) return false;
    phase_ = Phase::kEnding;
    parked_.reset();
    return true;
  }
  // The client half-closed (or went away): no more reads.
  void ReadingDone() { reading_ = Reading::kDone; }

  // Whether to start the next read now: not while the client leaves `max_answers` answers
  // unread (then reading is kPaused and WriteDone resumes). `paused_now`: reading has just
  // been paused (it was not). A caller that then reads calls ReadDecided before it lets go
  // of its lock.
  bool ShouldRead(int max_answers, bool* paused_now) {
    *paused_now = false;
    if (phase_ == Phase::kEnding || phase_ == Phase::kFinished || reading_ == Reading::kDone) return false;
    const bool pause = static_cast<int>(writes_.size()) >= max_answers;
    *paused_now = pause && reading_ != Reading::kPaused;
    reading_ = pause ? Reading::kPaused : Reading::kActive;
    return !pause;
  }
  // A read was decided on; it counts until ReadStarted: the stream must not finish in
  // between, as no read may start after the stream finished.
  void ReadDecided() { ++reads_starting_; }
  // The read decided on has been started; true if the stream should now pump (an ending or
  // half-closed stream finishes without waiting for the pending read: the finish Pump held
  // back).
  bool ReadStarted() {
    --reads_starting_;
    return reads_starting_ == 0 && (phase_ == Phase::kEnding || reading_ == Reading::kDone);
  }

  // Parks a step that arrived at `now`, returning the step it replaces, if any (that one is
  // answered as superseded).
  std::optional<Step> Park(Step step, Clock::time_point now) {
    std::optional<Step> superseded = std::exchange(parked_, std::move(step));
    parked_received_at_ = now;
    return superseded;
  }
  // The parked step, now being solved, if none is.
  std::optional<Step> TakeParked() {
    if (solving_ || !parked_.has_value()) return std::nullopt;
    std::optional<Step> step = std::move(parked_);
    parked_.reset();
    solving_received_at_ = parked_received_at_;
    solving_ = true;
    return step;
  }
  // The step being solved was answered (or could not be solved).
  void SolveEnded() { solving_ = false; }

  void QueueAnswer(const Answer& answer) { writes_.push_back(answer); }

  // What to do next when nothing else is happening: write the front answer (`*to_write`,
  // valid until WriteDone), finish the stream (once: the phase is then kFinished), or
  // nothing (a write, a solve, a read or an attach is under way).
  enum class Next { kNothing, kWrite, kFinish };
  Next Pump(const Answer** to_write) {
    *to_write = nullptr;
    if (phase_ == Phase::kFinished) return Next::kNothing;
    if (!writing_ && !writes_.empty()) {
      writing_ = true;
      *to_write = &writes_.front();
      return Next::kWrite;
    }
    if (!writing_ && !solving_ && reads_starting_ == 0 && phase_ != Phase::kAttaching &&
        (phase_ == Phase::kEnding || (reading_ == Reading::kDone && !parked_.has_value()))) {
      phase_ = Phase::kFinished;
      return Next::kFinish;
    }
    return Next::kNothing;
  }
  // The front answer was written (`ok`), or the client is gone: then what is left is dropped
  // and reading stops. True if reading resumes (it was paused and may go on now): the
  // caller calls ReadDecided and reads.
  bool WriteDone(bool ok, int max_answers) {
    writes_.pop_front();
    writing_ = false;
    if (!ok) {
      writes_.clear();
      parked_.reset();
      reading_ = Reading::kDone;
    }
    bool paused_now = false;  // never: reading was paused already
    return reading_ == Reading::kPaused && ShouldRead(max_answers, &paused_now);
  }

 private:
  Phase phase_ = Phase::kAwaitingFirst;
  Reading reading_ = Reading::kActive;
  std::optional<Step> parked_;              // the newest step not yet started
  Clock::time_point parked_received_at_{};  // when parked_ arrived
  Clock::time_point solving_received_at_{};
  bool solving_ = false;       // a step is being solved
  std::deque<Answer> writes_;  // front is being written when writing_
  bool writing_ = false;
  int reads_starting_ = 0;  // reads decided on but not started yet
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_STREAM_FLOW_H_
