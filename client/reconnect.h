#ifndef NUPMPC_CLIENT_RECONNECT_H_
#define NUPMPC_CLIENT_RECONNECT_H_

// How a nupmpc::Session rides through a broken Control stream (a server restart, a
// dropped connection): bounded retries with exponential back-off and jitter.
//
// When a step fails with a retryable code (IsRetryable: UNAVAILABLE, the code of a refused
// or dropped connection and of a draining server), the session waits d_k and tries to
// re-create its session, k = 0, 1, ..., where
//
//   d_k = min(initial_backoff · multiplier^k, max_backoff) · U(1 − jitter, 1 + jitter),
//
// U uniform, until an attempt succeeds (then the step is resent) or the `budget`, measured
// from the failure, is spent: no attempt starts after it (the last wait is shortened to
// end at it), each attempt is cancelled after `attempt_timeout`, and after the last one the
// step fails with UNAVAILABLE. So a step returns within budget + attempt_timeout (plus
// the resent solve). Other codes (INVALID_ARGUMENT, RESOURCE_EXHAUSTED, ...) are returned
// at once: retrying cannot fix them.

#include <chrono>
#include <cstdint>
#include <functional>
#include <random>
#include <string>

#include "absl/status/status.h"

namespace nupmpc {

// One reconnect attempt, as reported to ReconnectOptions::on_attempt.
struct ReconnectAttempt {
  int attempt = 0;                       // 1, 2, ... within this outage; 0: none was made (a zero budget), gave_up
  std::chrono::milliseconds waited{0};   // the back-off slept before this attempt
  std::chrono::milliseconds elapsed{0};  // since the stream broke, after this attempt
  absl::Status cause;                    // what broke the stream (attempt 1) or the previous attempt
  absl::Status result;                   // this attempt: OK = reconnected
  bool gave_up = false;                  // the budget is spent (or the error is not retryable)
};

struct ReconnectOptions {
  std::chrono::milliseconds initial_backoff{50};
  double multiplier = 2.0;
  std::chrono::milliseconds max_backoff{2000};
  double jitter = 0.2;                      // each wait is drawn uniformly within ±jitter of d_k
  std::chrono::milliseconds budget{30000};  // per outage; 0: no reconnect at all
  // One attempt (connect, attach, session created) is cancelled after this long.
  std::chrono::milliseconds attempt_timeout{5000};
  std::uint64_t seed = 0;  // of the jitter; 0: drawn from std::random_device

  // Injectable for tests; empty: std::chrono::steady_clock::now and
  // std::this_thread::sleep_for.
  std::function<std::chrono::steady_clock::time_point()> now;
  std::function<void(std::chrono::milliseconds)> sleep;
  // Called after every attempt (e.g. to log it); empty: nothing.
  std::function<void(const ReconnectAttempt&)> on_attempt;
};

// Whether an error of a step or an attach is worth a reconnect.
bool IsRetryable(const absl::Status& status);

// The waits of one outage: Next() gives d_0, d_1, ... (jittered, as above).
class Backoff {
 public:
  explicit Backoff(const ReconnectOptions& options);
  std::chrono::milliseconds Next();
  // Back to d_0 (after a successful reconnect).
  void Reset() { attempt_ = 0; }
  // The un-jittered d_k of the next Next().
  std::chrono::milliseconds NominalNext() const;

 private:
  ReconnectOptions options_;
  int attempt_ = 0;
  std::mt19937_64 rng_;
};

// Runs `attempt` until it succeeds, fails with a non-retryable error, or the budget
// (from now) is spent, sleeping the back-off between attempts; `first_cause` is the error
// that started the outage. `attempt` gets options.attempt_timeout (to bound itself).
// Returns OK, the non-retryable error, or UNAVAILABLE naming the attempts, the time spent
// and the last error. `attempts` (optional) gets the number of attempts made.
absl::Status RetryWithBackoff(const ReconnectOptions& options, const absl::Status& first_cause,
                              const std::function<absl::Status(std::chrono::milliseconds)>& attempt,
                              int* attempts = nullptr);

// What a session's reconnects cost so far (nupmpc::Session, AddressedSession).
struct ReconnectStats {
  int reconnects = 0;                    // outages ridden through (session re-created, step answered)
  int attempts = 0;                      // attempts made, successful or not
  int failed_outages = 0;                // outages that spent the budget (the step returned UNAVAILABLE)
  std::chrono::milliseconds total{0};    // from each break to its step's answer (or giving up)
  std::chrono::milliseconds longest{0};  // the longest such outage
};

// One outage of a session, from the error that broke a step (`cause`) to that step's
// answer: RetryWithBackoff over `recreate_and_resend`, which re-creates the session and
// resends the step, sets *answered once the server answered the resent step (with a
// result or with an error of the step's own), and returns that call's status. Books the
// outage into `stats`. Returns OK when the step was answered (the caller holds the
// answer), else the error that ended the outage.
absl::Status RideOutOutage(
    const ReconnectOptions& options, const absl::Status& cause,
    const std::function<absl::Status(std::chrono::milliseconds, bool* answered)>& recreate_and_resend,
    ReconnectStats* stats);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_RECONNECT_H_
