#ifndef NUPMPC_CLIENT_RECONNECT_H_
#define NUPMPC_CLIENT_RECONNECT_H_

// How a nupmpc::Session rides through a broken Control stream (a server restart, a
// dropped connection): bounded retries with exponential back-off and jitter.
//
// When a step fails with a retryable code (IsRetryable: UNAVAILABLE, the code of a refused
// or dropped connection and of a draining server), the session waits d_k and tries to get
// its session back (ReattachOrRecreate below), k = 0, 1, ..., where
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
#include <optional>
#include <random>
#include <string>

#include "absl/status/status.h"

namespace nupmpc {

// How an attempt got its session back.
enum class ReconnectPath {
  kNone,        // it did not (the attempt failed)
  kReattached,  // attached by its id: the server kept it (or restored it): the warm start survives
  kRecreated,   // created anew from the spec the client holds, under a new id: it starts cold
};

// One reconnect attempt, as reported to ReconnectOptions::on_attempt.
struct ReconnectAttempt {
  int attempt = 0;                       // 1, 2, ... within this outage; 0: none was made (a zero budget), gave_up
  std::chrono::milliseconds waited{0};   // the back-off slept before this attempt
  std::chrono::milliseconds elapsed{0};  // since the stream broke, after this attempt
  absl::Status cause;                    // what broke the stream (attempt 1) or the previous attempt
  absl::Status result;                   // this attempt: OK = reconnected
  bool gave_up = false;                  // the budget is spent (or the error is not retryable)
  ReconnectPath path = ReconnectPath::kNone;
  // The attach by the old id this attempt made first (OK: re-attached); nullopt: none was
  // made (no id to attach to, or a client that only re-creates).
  std::optional<absl::Status> attach_by_id;
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
// that started the outage. `attempt` gets options.attempt_timeout (to bound itself) and
// the attempt's report, in which it may say how it went (path, attach_by_id) before the
// report goes to options.on_attempt.
// Returns OK, the non-retryable error, or UNAVAILABLE naming the attempts, the time spent
// and the last error. `attempts` (optional) gets the number of attempts made.
absl::Status RetryWithBackoff(const ReconnectOptions& options, const absl::Status& first_cause,
                              const std::function<absl::Status(std::chrono::milliseconds, ReconnectAttempt*)>& attempt,
                              int* attempts = nullptr);

// Whether a failed attach by id says the session is not to be had by its id: NOT_FOUND (the
// server neither holds it nor could restore it from a snapshot: it restarted without one,
// the window passed, or another replica answered) or FAILED_PRECONDITION (another stream
// holds it, e.g. the old one, which the server has not yet seen broken, or a server that
// closes a stream's own session with its stream). Then waiting cannot help: re-create.
bool AttachByIdMissed(const absl::Status& status);

// One attempt to get a broken stream's session back. First `attach_by_id` (when `id` is not
// empty): a server that kept the session, or restores it from the snapshot it wrote when
// it drained, hands it back with its warm start (iterates, policy, u[-1]), so the next plan
// continues the old one instead of starting cold, which for a non-convex prior may land in
// another local optimum. Only when that attach missed (AttachByIdMissed) is the session
// re-created by `recreate` from the spec the client holds. Any other error of the attach is
// the attempt's (UNAVAILABLE: the back-off tries again, by id first again). Sets
// report->path and report->attach_by_id.
absl::Status ReattachOrRecreate(const std::string& id, const std::function<absl::Status()>& attach_by_id,
                                const std::function<absl::Status()>& recreate, ReconnectAttempt* report);

// What a session's reconnects cost so far (nupmpc::Session, AddressedSession).
struct ReconnectStats {
  int reconnects = 0;                    // outages ridden through (session back, step answered)
  int reattached = 0;                    // of them, sessions attached again by their id (warm)
  int recreated = 0;                     // of them, sessions re-created from the spec (cold)
  int attempts = 0;                      // attempts made, successful or not
  int failed_outages = 0;                // outages that spent the budget (the step returned UNAVAILABLE)
  std::chrono::milliseconds total{0};    // from each break to its step's answer (or giving up)
  std::chrono::milliseconds longest{0};  // the longest such outage
};

// Books one reconnect that got its session back by `path` (and answered its step).
void CountReconnect(ReconnectPath path, ReconnectStats* stats);

// One outage of a session, from the error that broke a step (`cause`) to that step's
// answer: RetryWithBackoff over `reconnect_and_resend`, which gets the session back (and
// says how in the report's path), resends the step, sets *answered once the server
// answered the resent step (with a result or with an error of the step's own), and returns
// that call's status. Books the outage into `stats`. Returns OK when the step was answered
// (the caller holds the answer), else the error that ended the outage.
absl::Status RideOutOutage(const ReconnectOptions& options, const absl::Status& cause,
                           const std::function<absl::Status(std::chrono::milliseconds, ReconnectAttempt*,
                                                            bool* answered)>& reconnect_and_resend,
                           ReconnectStats* stats);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_RECONNECT_H_
