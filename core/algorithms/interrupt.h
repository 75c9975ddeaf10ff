#ifndef NUPMPC_CORE_ALGORITHMS_INTERRUPT_H_
#define NUPMPC_CORE_ALGORITHMS_INTERRUPT_H_

// Time limits and cancellation inside a message-passing pass.
//
// Checking a solve's limits between passes only is not enough: one pass of a large problem
// takes seconds (O(N·M³)) and would hold its worker long after the deadline. Every per-step
// loop of every pass (forward filters, backward filters and smoothers, polish passes, the
// objective evaluation, the discrete search) therefore polls an Interrupt
// every k time steps, with k chosen once per solve from the step's flop count so that
// two polls are about kFlopsBetweenChecks apart: on a small problem (M = 2, N = 20) a
// pass polls at most once, on a large one every step. A poll is a countdown; only every
// k-th reads the clock and the cancel flag.
//
// Once fired, an Interrupt stays fired: every loop that polls it returns at its next poll
// and the pass it belongs to is incomplete. Its outputs (the iterate, the carried NUP
// state it was updating) are then garbage: the driver discards the iterate and cold-starts
// the algorithm (core/session/session.cc).

#include <algorithm>
#include <climits>
#include <optional>

#include "core/options.h"
#include "core/public/deadline.h"
#include "core/solution.h"

namespace nupmpc::core {

class Interrupt {
 public:
  using Clock = Deadline::Clock;
  // About 2·10⁶ flops between two clock reads: ≤ 1 ms at 2 GFLOP/s (20 ms even at a
  // sanitizer's 0.1 GFLOP/s), while a clock read (~25 ns) costs < 0.1 % of that work.
  static constexpr double kFlopsBetweenChecks = 2e6;

  // An interrupt that never fires.
  Interrupt() = default;
  // Fires when the limits' cancel flag is raised (kCancelled) or their time limit, counted
  // from `start`, has passed (kTimeLimit); a time limit of Deadline::kNeverSeconds or more
  // never fires. `flops_per_step`: one time step of one pass (EstimateFootprint), which
  // sets pass_interval().
  Interrupt(const SolveLimits& limits, Clock::time_point start, double flops_per_step)
      : stop_(Deadline::After(limits.time_limit_seconds, limits.cancel, start)) {
    pass_interval_ = IntervalFor(flops_per_step);
  }

  // Reads the flag and the clock now. Sticky: true from the first time it is true.
  bool CheckNow() {
    if (fired_.has_value()) return true;
    if (!stop_.armed()) return false;
    if (stop_.Cancelled()) {
      fired_ = SolveStatus::kCancelled;
    } else if (stop_.Passed()) {
      fired_ = SolveStatus::kTimeLimit;
    }
    return fired_.has_value();
  }
  bool fired() const { return fired_.has_value(); }
  // kCancelled or kTimeLimit once fired.
  std::optional<SolveStatus> reason() const { return fired_; }

  // Steps between two clock reads for a loop whose step costs `step_flops`.
  int IntervalFor(double step_flops) const {
    if (!stop_.armed()) return INT_MAX;
    if (!(step_flops > 0.0)) return INT_MAX / 2;
    return static_cast<int>(std::clamp(kFlopsBetweenChecks / step_flops, 1.0, static_cast<double>(INT_MAX / 2)));
  }
  // The interval of the passes' per-step loops (one step: flops_per_step).
  int pass_interval() const { return pass_interval_; }

 private:
  Deadline stop_;
  int pass_interval_ = INT_MAX;
  std::optional<SolveStatus> fired_;
};

// Between passes: whether `interrupt` fires now (reads the clock and the flag); if so its
// reason becomes the summary's status.
inline bool StopNow(Interrupt* interrupt, SolveSummary* summary) {
  if (!interrupt->CheckNow()) return false;
  summary->status = *interrupt->reason();
  return true;
}

// The poll of one loop: call once per step; true (and from then on always true) when the
// interrupt has fired, read every `interval` calls. A null interrupt never fires.
class StopPoll {
 public:
  StopPoll(Interrupt* interrupt, int interval)
      : interrupt_(interrupt),
        interval_(std::max(interval, 1)),
        left_(interrupt != nullptr && interrupt->fired() ? 1 : interval_) {}
  // With the passes' interval.
  explicit StopPoll(Interrupt* interrupt)
      : StopPoll(interrupt, interrupt != nullptr ? interrupt->pass_interval() : INT_MAX) {}
  bool operator()() {
    if (interrupt_ == nullptr) return false;
    if (--left_ > 0) return false;
    if (interrupt_->CheckNow()) {
      left_ = 1;  // fired: every later call answers true
      return true;
    }
    left_ = interval_;
    return false;
  }

 private:
  Interrupt* interrupt_;
  int interval_;
  int left_;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_INTERRUPT_H_
