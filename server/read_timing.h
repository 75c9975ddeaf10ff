#ifndef NUPMPC_SERVER_READ_TIMING_H_
#define NUPMPC_SERVER_READ_TIMING_H_

#include <chrono>

namespace nupmpc::server {

// When a Control stream reads its next step, for steps solved on the gRPC thread that read
// them (short solves): ahead, before the solve, or after it.
//
// Ahead is what newest-state-wins needs from a client that sends before it has its answer
// (open loop, bursts): the steps that arrive during a solve are read, and each replaces
// the one waiting. But a read pending while the thread solves costs the service a chain of
// wake-ups between gRPC's threads on the solve's core, on the round trip's critical path
// (measured in the README: 4-8 % of the solves per second of a closed loop). A client that
// waits for each answer before it sends the next step (a closed loop) sends nothing during
// the solve, so for it reading after the solve loses nothing.
//
// The stream starts reading ahead. It reads after once kClosedLoopSteps steps in a row
// arrived with none of its steps being solved (the client waited for its answers), and
// goes back to reading ahead at the first sign of a step sent before its answer: one that
// arrives while another is being solved, or one that a read started after a solve finds
// already there: it completes within kAlreadyThere, or before gRPC has finished writing
// the answer the read was held back for (a closed loop's client has not seen that answer
// yet; a loaded machine delays both callbacks alike, so one of the two signs shows). The
// step that showed it is then read ahead of, so a burst is superseded as before from its
// second step on.
class ReadTiming {
 public:
  static constexpr int kClosedLoopSteps = 4;
  static constexpr std::chrono::microseconds kAlreadyThere{15};

  // A step arrived: `solving` whether another of the stream's steps was being solved,
  // `read_after` whether its read was started after a solve, `waited` how long that read
  // was pending, `answer_unsent` whether an answer of the stream is still being written.
  void StepArrived(bool solving, bool read_after, std::chrono::steady_clock::duration waited, bool answer_unsent);
  // Whether the next in-place solve's read starts before it.
  bool ahead() const { return ahead_; }

 private:
  bool ahead_ = true;
  int closed_loop_steps_ = 0;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_READ_TIMING_H_
