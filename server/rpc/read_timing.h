#ifndef NUPMPC_SERVER_RPC_READ_TIMING_H_
#define NUPMPC_SERVER_RPC_READ_TIMING_H_

#include <chrono>

namespace nupmpc::server {

// When a Control stream reads its next step, for steps solved on the gRPC thread that read
// them (short solves): ahead, before the solve, or after it.
//
// Ahead is what newest-state-wins needs from a client that sends before it has its answer
// (open loop, bursts): the steps that arrive during a solve are read, and each replaces
// the one waiting. But a read pending while the thread solves costs the service a chain of
// wake-ups between gRPC's threads on the solve's core, on the round trip's critical path
// (server/README.md, "When a stream reads its next step"). A client that
// waits for each answer before it sends the next step (a closed loop) sends nothing during
// the solve, so for it reading after the solve loses nothing.
//
// The stream starts reading ahead. It reads after once kClosedLoopSteps steps in a row
// arrived with none of its steps being solved (the client waited for its answers), and
// goes back to reading ahead at the first sign of a step sent before its answer: one that
// arrives while another is being solved or before gRPC has finished writing an answer of
// the stream (a closed loop's client has not seen that answer yet), or one that a read
// started after a solve finds already there (it completes within kAlreadyThere). These
// signs depend on how soon gRPC's callbacks run, so while reading after, every
// kProbeSteps-th step is read ahead of all the same: a client sending ahead then shows it
// by the step gRPC delivers during that solve. (Superseding among steps solved in place
// always depended on gRPC's other thread delivering the next step during the solve.) The
// step that showed it is read ahead of.
class ReadTiming {
 public:
  static constexpr int kClosedLoopSteps = 4;
  static constexpr int kProbeSteps = 8;
  static constexpr std::chrono::microseconds kAlreadyThere{15};

  // A step arrived: `solving` whether another of the stream's steps was being solved,
  // `read_after` whether its read was started after a solve, `waited` how long that read
  // was pending, `answer_unsent` whether an answer of the stream is still being written.
  void StepArrived(bool solving, bool read_after, std::chrono::steady_clock::duration waited, bool answer_unsent);
  // Whether the step that arrived last is read ahead of, should it be solved in place.
  bool ReadAhead();
  // Whether the stream reads ahead of every step (else after, but for the probes).
  bool ahead() const { return ahead_; }

 private:
  bool ahead_ = true;
  int closed_loop_steps_ = 0;
  int steps_since_probe_ = 0;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_READ_TIMING_H_
