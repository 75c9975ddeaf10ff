#ifndef NUPMPC_CORE_GP_INTERRUPT_H_
#define NUPMPC_CORE_GP_INTERRUPT_H_

// When a long GP computation (kernel matrix, factorisation, inverse, likelihood) must stop:
// a deadline and a cancel flag, both checked between blocks of work whose size bounds how
// long a worker stays busy after either fires. The check costs one clock read.

#include <atomic>
#include <chrono>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace nupmpc::gp {

struct Interrupt {
  using Clock = std::chrono::steady_clock;
  Clock::time_point deadline = Clock::time_point::max();  ///< max(): none
  const std::atomic<bool>* cancel = nullptr;

  // No deadline when seconds ≤ 0 (the FitOptions.max_seconds convention).
  static Interrupt After(double seconds, const std::atomic<bool>* cancel) {
    Interrupt stop;
    stop.cancel = cancel;
    if (seconds > 0.0) {
      stop.deadline =
          Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
    }
    return stop;
  }

  bool Cancelled() const { return cancel != nullptr && cancel->load(std::memory_order_relaxed); }
  bool Requested() const { return Cancelled() || (deadline != Clock::time_point::max() && Clock::now() >= deadline); }
  // CANCELLED or DEADLINE_EXCEEDED (whichever fired; call after Requested() returned true)
  // saying where the work stopped, e.g. "factorising K + σ_n² I (column 1024 of 5000)".
  absl::Status Stopped(absl::string_view where) const {
    if (Cancelled()) return absl::CancelledError(absl::StrCat("cancelled while ", where));
    return absl::DeadlineExceededError(absl::StrCat("the deadline passed while ", where));
  }
};

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_INTERRUPT_H_
