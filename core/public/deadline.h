#ifndef NUPMPC_CORE_PUBLIC_DEADLINE_H_
#define NUPMPC_CORE_PUBLIC_DEADLINE_H_

// When long work must stop: a deadline and a cancel flag, the one type for both. The
// solver's passes poll it through an Interrupt (core/algorithms/interrupt.h), the GP
// computations between blocks of work (core/gp/), the server around them. A check costs
// one clock read.

#include <atomic>
#include <chrono>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace nupmpc::core {

struct Deadline {
  using Clock = std::chrono::steady_clock;
  // A time limit of kNeverSeconds or more never passes: it is past any computation, and
  // larger ones would overflow the clock's 64-bit nanoseconds (292 years) when added to a
  // start.
  static constexpr double kNeverSeconds = 1e9;

  Clock::time_point at = Clock::time_point::max();  ///< max(): none
  const std::atomic<bool>* cancel = nullptr;        ///< none when null

  // `seconds` after `start`; no deadline when seconds ≤ 0 (the convention of
  // SolveLimits.time_limit_seconds and FitOptions.max_seconds) or ≥ kNeverSeconds.
  static Deadline After(double seconds, const std::atomic<bool>* cancel, Clock::time_point start = Clock::now()) {
    Deadline stop;
    stop.cancel = cancel;
    if (seconds > 0.0 && seconds < kNeverSeconds) {
      stop.at = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
    }
    return stop;
  }

  bool has_deadline() const { return at != Clock::time_point::max(); }
  // Whether it can ever fire.
  bool armed() const { return has_deadline() || cancel != nullptr; }
  bool Cancelled() const { return cancel != nullptr && cancel->load(std::memory_order_relaxed); }
  bool Passed() const { return has_deadline() && Clock::now() >= at; }
  bool Requested() const { return Cancelled() || Passed(); }
  // CANCELLED or DEADLINE_EXCEEDED (whichever fired; call after Requested() returned true)
  // saying where the work stopped, e.g. "factorising K + σ_n² I (column 1024 of 5000)".
  absl::Status Stopped(absl::string_view where) const {
    if (Cancelled()) return absl::CancelledError(absl::StrCat("cancelled while ", where));
    return absl::DeadlineExceededError(absl::StrCat("the deadline passed while ", where));
  }
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_PUBLIC_DEADLINE_H_
