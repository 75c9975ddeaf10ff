#include "server/rpc/read_timing.h"

namespace nupmpc::server {

void ReadTiming::StepArrived(bool solving, bool read_after, std::chrono::steady_clock::duration waited,
                             bool answer_unsent) {
  const bool sent_before_its_answer = solving || answer_unsent || (read_after && waited < kAlreadyThere);
  if (sent_before_its_answer) {
    ahead_ = true;
    closed_loop_steps_ = 0;
    steps_since_probe_ = 0;
  } else if (ahead_ && ++closed_loop_steps_ >= kClosedLoopSteps) {
    ahead_ = false;
  }
}

bool ReadTiming::ReadAhead() {
  if (ahead_) return true;
  if (++steps_since_probe_ < kProbeSteps) return false;
  steps_since_probe_ = 0;
  return true;
}

}  // namespace nupmpc::server
