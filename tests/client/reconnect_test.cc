// The back-off schedule of a Session's reconnects (client/reconnect.h), on a fake clock:
// growth, cap, jitter range, the budget, which errors are retried at all, and which way an
// attempt gets the session back (re-attached by its id, or re-created).
#include "client/reconnect.h"

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc {
namespace {

using std::chrono::milliseconds;

// A clock that only moves when the code under test sleeps (or an attempt takes time).
struct FakeTime {
  std::chrono::steady_clock::time_point now{};
  std::vector<milliseconds> sleeps;
  void Install(ReconnectOptions* options) {
    options->now = [this] { return now; };
    options->sleep = [this](milliseconds d) {
      sleeps.push_back(d);
      now += d;
    };
  }
};

TEST(Backoff, GrowsByTheFactorUpToTheCapWithoutJitter) {
  ReconnectOptions options;
  options.initial_backoff = milliseconds(50);
  options.multiplier = 2.0;
  options.max_backoff = milliseconds(2000);
  options.jitter = 0.0;
  Backoff backoff(options);
  std::vector<long long> waits;
  for (int k = 0; k < 9; ++k) waits.push_back(backoff.Next().count());
  EXPECT_THAT(waits, ::testing::ElementsAre(50, 100, 200, 400, 800, 1600, 2000, 2000, 2000));
  backoff.Reset();
  EXPECT_EQ(backoff.Next(), milliseconds(50));
}

TEST(Backoff, JitterStaysWithinItsRangeAndVaries) {
  ReconnectOptions options;  // defaults: 50 ms, ×2, 2 s, ±20 %
  options.seed = 7;
  for (int run = 0; run < 50; ++run) {
    options.seed = 7 + run;
    Backoff backoff(options);
    std::vector<long long> first;
    for (int k = 0; k < 10; ++k) {
      const milliseconds nominal = backoff.NominalNext();
      const milliseconds wait = backoff.Next();
      EXPECT_GE(wait.count(), std::llround(0.8 * nominal.count())) << "k " << k;
      EXPECT_LE(wait.count(), std::llround(1.2 * nominal.count())) << "k " << k;
      EXPECT_LE(wait, milliseconds(2400));
    }
  }
  // Different seeds give different schedules (the jitter is drawn, not fixed).
  std::vector<long long> a, b;
  options.seed = 1;
  Backoff first(options);
  options.seed = 2;
  Backoff second(options);
  for (int k = 0; k < 8; ++k) {
    a.push_back(first.Next().count());
    b.push_back(second.Next().count());
  }
  EXPECT_NE(a, b);
}

TEST(RetryWithBackoff, RetriesUnavailableUntilItSucceeds) {
  ReconnectOptions options;
  options.jitter = 0.0;
  FakeTime time;
  time.Install(&options);
  std::vector<ReconnectAttempt> reported;
  options.on_attempt = [&](const ReconnectAttempt& a) { reported.push_back(a); };
  int calls = 0;
  int attempts = 0;
  const absl::Status s = RetryWithBackoff(
      options, absl::UnavailableError("stream broke"),
      [&](milliseconds timeout, ReconnectAttempt*) {
        EXPECT_EQ(timeout, options.attempt_timeout);
        return ++calls < 4 ? absl::UnavailableError("connection refused") : absl::OkStatus();
      },
      &attempts);
  EXPECT_TRUE(s.ok()) << s;
  EXPECT_EQ(attempts, 4);
  EXPECT_THAT(time.sleeps,
              ::testing::ElementsAre(milliseconds(50), milliseconds(100), milliseconds(200), milliseconds(400)));
  ASSERT_EQ(reported.size(), 4u);
  EXPECT_EQ(reported[0].cause.message(), "stream broke");
  EXPECT_EQ(reported[1].cause.message(), "connection refused");
  EXPECT_TRUE(reported[3].result.ok());
  EXPECT_EQ(reported[3].elapsed, milliseconds(750));
  EXPECT_FALSE(reported[3].gave_up);
}

TEST(RetryWithBackoff, StopsAtTheBudgetShorteningTheLastWait) {
  ReconnectOptions options;
  options.budget = milliseconds(3000);
  options.seed = 3;  // ±20 % jitter
  FakeTime time;
  time.Install(&options);
  std::vector<ReconnectAttempt> reported;
  options.on_attempt = [&](const ReconnectAttempt& a) { reported.push_back(a); };
  int attempts = 0;
  const absl::Status s = RetryWithBackoff(
      options, absl::UnavailableError("stream broke"),
      [&](milliseconds, ReconnectAttempt*) {
        time.now += milliseconds(5);  // each refused connect takes a little time
        return absl::UnavailableError("connection refused");
      },
      &attempts);
  EXPECT_TRUE(absl::IsUnavailable(s)) << s;
  EXPECT_THAT(std::string(s.message()), ::testing::HasSubstr("gave up reconnecting"));
  EXPECT_THAT(std::string(s.message()), ::testing::HasSubstr("connection refused"));
  // No attempt starts after the budget; the last one starts exactly at it.
  const auto total = std::chrono::duration_cast<milliseconds>(time.now - std::chrono::steady_clock::time_point{});
  EXPECT_GE(total, milliseconds(3000));
  EXPECT_LE(total, milliseconds(3000 + 5));
  ASSERT_EQ(static_cast<int>(reported.size()), attempts);
  EXPECT_GE(attempts, 5);  // 50+100+200+400+800 ≈ 1.55 s (±20 %) before the budget
  EXPECT_TRUE(reported.back().gave_up);
  for (std::size_t k = 0; k + 1 < reported.size(); ++k) EXPECT_FALSE(reported[k].gave_up) << k;
  // Waits grow (beyond the jitter) until the cap or the budget cuts them.
  for (std::size_t k = 1; k + 1 < time.sleeps.size(); ++k) EXPECT_GT(time.sleeps[k], time.sleeps[k - 1]) << k;
}

TEST(RetryWithBackoff, DoesNotRetryWhatRetryingCannotFix) {
  ReconnectOptions options;
  FakeTime time;
  time.Install(&options);
  int calls = 0;
  for (const absl::Status& error : {absl::InvalidArgumentError("bad spec"), absl::ResourceExhaustedError("full"),
                                    absl::PermissionDeniedError("no")}) {
    calls = 0;
    const absl::Status s =
        RetryWithBackoff(options, absl::UnavailableError("stream broke"), [&](milliseconds, ReconnectAttempt*) {
          ++calls;
          return error;
        });
    EXPECT_EQ(s, error);
    EXPECT_EQ(calls, 1);
  }
  EXPECT_TRUE(IsRetryable(absl::UnavailableError("x")));
  EXPECT_FALSE(IsRetryable(absl::InvalidArgumentError("x")));
  EXPECT_FALSE(IsRetryable(absl::DeadlineExceededError("x")));
  EXPECT_FALSE(IsRetryable(absl::OkStatus()));
}

TEST(RetryWithBackoff, AZeroBudgetMakesNoAttempt) {
  ReconnectOptions options;
  options.budget = milliseconds(0);
  FakeTime time;
  time.Install(&options);
  int calls = 0;
  const absl::Status s =
      RetryWithBackoff(options, absl::UnavailableError("stream broke"), [&](milliseconds, ReconnectAttempt*) {
        ++calls;
        return absl::OkStatus();
      });
  EXPECT_TRUE(absl::IsUnavailable(s));
  EXPECT_EQ(calls, 0);
  EXPECT_TRUE(time.sleeps.empty());
}

// The decision of one attempt (ReattachOrRecreate): what the attach by id answered decides
// whether the session is re-created, and the report says which way it went.
struct ScriptedAttempt {
  absl::Status attach, create;
  int attaches = 0, creates = 0;
  absl::Status Run(const std::string& id, ReconnectAttempt* report) {
    return ReattachOrRecreate(
        id,
        [&] {
          ++attaches;
          return attach;
        },
        [&] {
          ++creates;
          return create;
        },
        report);
  }
};

TEST(ReattachOrRecreate, ASessionHandedBackIsReattachedWithoutRecreating) {
  ScriptedAttempt a{absl::OkStatus(), absl::OkStatus()};
  ReconnectAttempt report;
  EXPECT_TRUE(a.Run("id", &report).ok());
  EXPECT_EQ(a.attaches, 1);
  EXPECT_EQ(a.creates, 0);
  EXPECT_EQ(report.path, ReconnectPath::kReattached);
  ASSERT_TRUE(report.attach_by_id.has_value());
  EXPECT_TRUE(report.attach_by_id->ok());
}

TEST(ReattachOrRecreate, NotFoundOrHeldElsewhereRecreatesInTheSameAttempt) {
  for (const absl::Status& missed : {absl::NotFoundError("no such session"),
                                     absl::FailedPreconditionError("another Control stream is attached to it")}) {
    ScriptedAttempt a{missed, absl::OkStatus()};
    ReconnectAttempt report;
    EXPECT_TRUE(a.Run("id", &report).ok());
    EXPECT_EQ(a.attaches, 1);
    EXPECT_EQ(a.creates, 1);
    EXPECT_EQ(report.path, ReconnectPath::kRecreated);
    EXPECT_EQ(report.attach_by_id, missed);
    // A re-creation that fails is the attempt's error; nothing came back.
    ScriptedAttempt refused{missed, absl::UnavailableError("connection refused")};
    EXPECT_TRUE(absl::IsUnavailable(refused.Run("id", &report)));
    EXPECT_EQ(report.path, ReconnectPath::kNone);
  }
}

TEST(ReattachOrRecreate, OtherErrorsAreTheAttemptsAndRecreateNothing) {
  // UNAVAILABLE: the server (or the one the id routes to) is not there yet; the back-off
  // tries the id again. The others: re-creating would be refused the same way.
  for (const absl::Status& error : {absl::UnavailableError("restarting"), absl::PermissionDeniedError("no"),
                                    absl::UnauthenticatedError("no token")}) {
    ScriptedAttempt a{error, absl::OkStatus()};
    ReconnectAttempt report;
    EXPECT_EQ(a.Run("id", &report), error);
    EXPECT_EQ(a.creates, 0);
    EXPECT_EQ(report.path, ReconnectPath::kNone);
  }
  EXPECT_TRUE(AttachByIdMissed(absl::NotFoundError("x")));
  EXPECT_TRUE(AttachByIdMissed(absl::FailedPreconditionError("x")));
  EXPECT_FALSE(AttachByIdMissed(absl::UnavailableError("x")));
  EXPECT_FALSE(AttachByIdMissed(absl::OkStatus()));
}

TEST(ReattachOrRecreate, WithoutAnIdItCreates) {
  ScriptedAttempt a{absl::OkStatus(), absl::OkStatus()};
  ReconnectAttempt report;
  EXPECT_TRUE(a.Run("", &report).ok());
  EXPECT_EQ(a.attaches, 0);
  EXPECT_EQ(a.creates, 1);
  EXPECT_EQ(report.path, ReconnectPath::kRecreated);
  EXPECT_FALSE(report.attach_by_id.has_value());
}

// An outage on a fake clock: the server is down for two attempts (UNAVAILABLE), then
// answers the attach by id as the test says; the step is resent only by the attempt that
// got the session back, and the outage is booked by how it came back.
TEST(RideOutOutage, BooksReattachedAndRecreatedAndResendsOnlyWhenTheSessionIsBack) {
  for (const bool kept : {true, false}) {
    ReconnectOptions options;
    options.jitter = 0.0;
    FakeTime time;
    time.Install(&options);
    std::vector<ReconnectAttempt> reported;
    options.on_attempt = [&](const ReconnectAttempt& a) { reported.push_back(a); };
    ReconnectStats stats;
    int calls = 0, resent = 0;
    const absl::Status s = RideOutOutage(
        options, absl::UnavailableError("the Control stream broke"),
        [&](milliseconds, ReconnectAttempt* report, bool* answered) {
          ++calls;
          const absl::Status attach = calls < 3 ? absl::UnavailableError("connection refused")
                                      : kept    ? absl::OkStatus()
                                                : absl::NotFoundError("no such session");
          absl::Status back = ReattachOrRecreate(
              "id", [&] { return attach; }, [] { return absl::OkStatus(); }, report);
          if (!back.ok()) return back;
          ++resent;
          *answered = true;
          return absl::OkStatus();
        },
        &stats);
    EXPECT_TRUE(s.ok()) << s;
    EXPECT_EQ(resent, 1);
    EXPECT_EQ(stats.attempts, 3);
    EXPECT_EQ(stats.reconnects, 1);
    EXPECT_EQ(stats.reattached, kept ? 1 : 0);
    EXPECT_EQ(stats.recreated, kept ? 0 : 1);
    ASSERT_EQ(reported.size(), 3u);
    EXPECT_EQ(reported[0].path, ReconnectPath::kNone);
    EXPECT_EQ(reported[2].path, kept ? ReconnectPath::kReattached : ReconnectPath::kRecreated);
  }
}

}  // namespace
}  // namespace nupmpc
