#include "client/reconnect.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include "absl/strings/str_cat.h"

namespace nupmpc {

bool IsRetryable(const absl::Status& status) { return absl::IsUnavailable(status); }

Backoff::Backoff(const ReconnectOptions& options)
    : options_(options), rng_(options.seed != 0 ? options.seed : std::random_device{}()) {}

std::chrono::milliseconds Backoff::NominalNext() const {
  const double initial = static_cast<double>(std::max<std::int64_t>(options_.initial_backoff.count(), 0));
  const double cap = static_cast<double>(std::max<std::int64_t>(options_.max_backoff.count(), 0));
  const double grown = initial * std::pow(std::max(options_.multiplier, 1.0), attempt_);
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::llround(std::min(grown, cap))));
}

std::chrono::milliseconds Backoff::Next() {
  const double nominal = static_cast<double>(NominalNext().count());
  ++attempt_;
  const double jitter = std::clamp(options_.jitter, 0.0, 1.0);
  std::uniform_real_distribution<double> factor(1.0 - jitter, 1.0 + jitter);
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::llround(nominal * factor(rng_))));
}

absl::Status RetryWithBackoff(const ReconnectOptions& options, const absl::Status& first_cause,
                              const std::function<absl::Status(std::chrono::milliseconds, ReconnectAttempt*)>& attempt,
                              int* attempts) {
  using std::chrono::milliseconds;
  const auto now = [&] { return options.now ? options.now() : std::chrono::steady_clock::now(); };
  const auto sleep = [&](milliseconds d) {
    if (d.count() <= 0) return;
    if (options.sleep) {
      options.sleep(d);
    } else {
      std::this_thread::sleep_for(d);
    }
  };
  const auto start = now();
  const auto elapsed = [&] { return std::chrono::duration_cast<milliseconds>(now() - start); };
  Backoff backoff(options);
  absl::Status last = first_cause;
  int made = 0;
  if (attempts != nullptr) *attempts = 0;
  while (elapsed() < options.budget) {
    const milliseconds wait = std::min(backoff.Next(), options.budget - elapsed());
    sleep(wait);
    ReconnectAttempt report;
    report.attempt = ++made;
    report.waited = wait;
    report.cause = last;
    report.result = attempt(options.attempt_timeout, &report);
    report.elapsed = elapsed();
    if (attempts != nullptr) *attempts = made;
    const bool retryable = IsRetryable(report.result);
    report.gave_up = !report.result.ok() && (!retryable || report.elapsed >= options.budget);
    if (options.on_attempt) options.on_attempt(report);
    if (report.result.ok() || !retryable) return report.result;
    last = report.result;
  }
  if (made == 0 && options.on_attempt) {
    ReconnectAttempt report;
    report.cause = first_cause;
    report.result = first_cause;
    report.gave_up = true;
    options.on_attempt(report);
  }
  return absl::UnavailableError(absl::StrCat("gave up reconnecting after ", made, " attempt(s) in ", elapsed().count(),
                                             " ms (budget ", options.budget.count(),
                                             " ms); last error: ", last.ToString()));
}

bool AttachByIdMissed(const absl::Status& status) {
  return absl::IsNotFound(status) || absl::IsFailedPrecondition(status);
}

absl::Status ReattachOrRecreate(const std::string& id, const std::function<absl::Status()>& attach_by_id,
                                const std::function<absl::Status()>& recreate, ReconnectAttempt* report) {
  report->path = ReconnectPath::kNone;
  report->attach_by_id.reset();
  if (!id.empty()) {
    absl::Status attached = attach_by_id();
    report->attach_by_id = attached;
    if (attached.ok()) {
      report->path = ReconnectPath::kReattached;
      return attached;
    }
    if (!AttachByIdMissed(attached)) return attached;
  }
  absl::Status created = recreate();
  if (created.ok()) report->path = ReconnectPath::kRecreated;
  return created;
}

void CountReconnect(ReconnectPath path, ReconnectStats* stats) {
  ++stats->reconnects;
  if (path == ReconnectPath::kReattached) ++stats->reattached;
  if (path == ReconnectPath::kRecreated) ++stats->recreated;
}

absl::Status RideOutOutage(const ReconnectOptions& options, const absl::Status& cause,
                           const std::function<absl::Status(std::chrono::milliseconds, ReconnectAttempt*,
                                                            bool* answered)>& reconnect_and_resend,
                           ReconnectStats* stats) {
  const auto now = [&] { return options.now ? options.now() : std::chrono::steady_clock::now(); };
  const auto start = now();
  int attempts = 0;
  bool answered = false;
  ReconnectPath path = ReconnectPath::kNone;
  absl::Status outage = RetryWithBackoff(
      options, cause,
      [&](std::chrono::milliseconds timeout, ReconnectAttempt* report) {
        absl::Status s = reconnect_and_resend(timeout, report, &answered);
        path = report->path;
        return s;
      },
      &attempts);
  const auto took = std::chrono::duration_cast<std::chrono::milliseconds>(now() - start);
  stats->attempts += attempts;
  stats->total += took;
  stats->longest = std::max(stats->longest, took);
  if (answered) {
    // The attempt that got the answer is the last one made: its path is the outage's.
    CountReconnect(path, stats);
    return absl::OkStatus();
  }
  if (IsRetryable(outage)) ++stats->failed_outages;
  return outage;
}

}  // namespace nupmpc
