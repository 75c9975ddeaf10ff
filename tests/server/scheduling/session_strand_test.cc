// A session's strand: its tasks run one at a time and in order, a waiting task holds no
// worker (another session's work runs meanwhile on the second worker), the wait is
// bounded, and tasks the pool refuses when it is their turn are answered through `fail`.
#include "server/scheduling/session_strand.h"

#include <atomic>
#include <chrono>
#include <functional>
#include <future>
#include <mutex>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

using namespace std::chrono_literals;

SessionStrand::Task Task(std::function<void()> run, std::atomic<int>* failures = nullptr) {
  return {std::move(run), [failures](absl::Status) {
            if (failures != nullptr) ++*failures;
          }};
}

// A task of `strand` that is running (the constructor returns once it started) and
// blocks its worker until Release(); then it runs `after`.
class TaskInFlight {
 public:
  TaskInFlight(
      const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool, std::function<void()> after = [] {})
      : released_(release_.get_future().share()) {
    std::future<void> running = started_.get_future();
    EXPECT_TRUE(SessionStrand::Submit(strand, pool, Task([this, after = std::move(after)] {
                                        started_.set_value();
                                        released_.wait();
                                        after();
                                      }))
                    .ok());
    running.wait();
  }
  void Release() { release_.set_value(); }

 private:
  // Members, not locals: the task still uses them after the constructor has returned.
  std::promise<void> started_, release_;
  std::shared_future<void> released_;
};

TEST(SessionStrand, WaitingTasksHoldNoWorkerAndRunInOrder) {
  WorkerPool pool(/*threads=*/2, /*queue_capacity=*/64);
  auto strand = std::make_shared<SessionStrand>();
  std::promise<void> first_started, release_first;
  std::shared_future<void> released = release_first.get_future().share();
  std::atomic<int> running{0}, most_running{0};
  std::vector<int> order;
  std::mutex order_mu;
  const auto record = [&](int i) {
    const int now = ++running;
    most_running = std::max(most_running.load(), now);
    {
      std::lock_guard<std::mutex> lock(order_mu);
      order.push_back(i);
    }
    --running;
  };
  ASSERT_TRUE(SessionStrand::Submit(strand, pool, Task([&] {
                                      first_started.set_value();
                                      record(0);
                                      released.wait();
                                    }))
                  .ok());
  first_started.get_future().wait();
  for (int i = 1; i <= 3; ++i) ASSERT_TRUE(SessionStrand::Submit(strand, pool, Task([&, i] { record(i); })).ok());
  EXPECT_EQ(strand->waiting(), 3);

  // Another session's work gets the second worker while the first session's task blocks.
  std::promise<void> other_done;
  ASSERT_TRUE(pool.TrySubmit([&] { other_done.set_value(); }).ok());
  EXPECT_EQ(other_done.get_future().wait_for(10s), std::future_status::ready)
      << "a task waiting for its session held the other worker";

  release_first.set_value();
  // Until every task has run (waiting() falls to 0 as the last one leaves the strand, before
  // it has run; the pool's shutdown does not wait for what it has not started).
  const auto recorded = [&] {
    std::lock_guard<std::mutex> lock(order_mu);
    return order.size();
  };
  for (int spin = 0; spin < 10000 && recorded() < 4; ++spin) std::this_thread::sleep_for(1ms);
  pool.Shutdown();
  EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(most_running.load(), 1);
}

TEST(SessionStrand, RefusesBeyondTheWaitBoundAndFailsWhatThePoolRefuses) {
  WorkerPool pool(/*threads=*/1, /*queue_capacity=*/64);
  auto strand = std::make_shared<SessionStrand>();
  TaskInFlight in_flight(strand, pool);
  std::atomic<int> ran{0}, failures{0};
  for (int i = 0; i < SessionStrand::kMaxWaiting; ++i) {
    ASSERT_TRUE(SessionStrand::Submit(strand, pool, Task([&] { ++ran; }, &failures)).ok());
  }
  const absl::Status refused = SessionStrand::Submit(strand, pool, Task([&] { ++ran; }, &failures));
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(refused.message()), ::testing::HasSubstr("session_id"));

  // Shutting down while tasks wait for the session: each is answered exactly once.
  std::thread stopper([&] { pool.Shutdown(); });
  std::this_thread::sleep_for(20ms);  // Shutdown() has stopped accepting before the first task ends
  in_flight.Release();
  stopper.join();
  EXPECT_EQ(ran.load() + failures.load(), SessionStrand::kMaxWaiting);
  EXPECT_EQ(strand->waiting(), 0);
}

// Closing and compaction run as the strand's work: at once on the calling thread when the
// session is idle; a close waits for the task in flight and runs before the waiting ones;
// compaction skips a busy session.
TEST(SessionStrand, ExclusiveWorkRunsNowWhenIdleAndRightAfterTheTaskInFlightOtherwise) {
  WorkerPool pool(/*threads=*/2, /*queue_capacity=*/64);
  auto strand = std::make_shared<SessionStrand>();
  const std::thread::id caller = std::this_thread::get_id();
  std::thread::id ran_on;
  SessionStrand::RunExclusive(strand, pool, [&] { ran_on = std::this_thread::get_id(); });
  EXPECT_EQ(ran_on, caller);
  bool compacted = false;
  EXPECT_TRUE(SessionStrand::RunNowIfIdle(strand, pool, [&] { compacted = true; }));
  EXPECT_TRUE(compacted);

  std::vector<int> order;
  std::mutex order_mu;
  const auto record = [&](int i) {
    std::lock_guard<std::mutex> lock(order_mu);
    order.push_back(i);
  };
  TaskInFlight in_flight(strand, pool, [&] { record(0); });
  std::promise<void> last_ran;
  ASSERT_TRUE(SessionStrand::Submit(strand, pool, Task([&] {
                                      record(2);
                                      last_ran.set_value();
                                    }))
                  .ok());
  EXPECT_FALSE(SessionStrand::RunNowIfIdle(strand, pool, [&] { record(-1); }));  // busy: skipped
  std::promise<void> closed;
  SessionStrand::RunExclusive(strand, pool, [&] {
    record(1);
    closed.set_value();
  });
  EXPECT_EQ(strand->waiting(), 2);
  in_flight.Release();
  EXPECT_EQ(closed.get_future().wait_for(10s), std::future_status::ready);
  // Until the last task has run, not until the strand is empty: the last task leaves the
  // strand before the pool has it, and a pool shut down in between would refuse it.
  EXPECT_EQ(last_ran.get_future().wait_for(10s), std::future_status::ready);
  pool.Shutdown();
  EXPECT_THAT(order, ::testing::ElementsAre(0, 1, 2));
}

// A close queued behind a task still runs when the pool refuses it at its turn.
TEST(SessionStrand, ExclusiveWorkRunsEvenWhenThePoolRefusesIt) {
  WorkerPool pool(/*threads=*/1, /*queue_capacity=*/64);
  auto strand = std::make_shared<SessionStrand>();
  TaskInFlight in_flight(strand, pool);
  std::atomic<bool> closed{false};
  SessionStrand::RunExclusive(strand, pool, [&] { closed = true; });
  std::thread stopper([&] { pool.Shutdown(); });  // refuses new tasks, then waits for the running one
  bool refusing = false;
  for (int spin = 0; spin < 10000 && !refusing; ++spin) {
    refusing = pool.TrySubmit([] {}).code() == absl::StatusCode::kUnavailable;
    if (!refusing) std::this_thread::sleep_for(1ms);
  }
  EXPECT_TRUE(refusing);
  in_flight.Release();
  stopper.join();
  EXPECT_TRUE(closed);
}

TEST(SessionStrand, RunsHereOnlyWhenTheSessionAndACoreAreFree) {
  WorkerPool pool(2, 8);
  const auto strand = std::make_shared<SessionStrand>();
  std::thread::id ran_on;
  EXPECT_TRUE(SessionStrand::TryRunHere(strand, pool, [&] { ran_on = std::this_thread::get_id(); }));
  EXPECT_EQ(ran_on, std::this_thread::get_id());

  // The session busy on a worker (a core is still free): not here, and nothing changed.
  // (Every TaskInFlight lives to the end: its task uses it until it has finished.)
  TaskInFlight busy(strand, pool);
  bool ran = false;
  EXPECT_FALSE(SessionStrand::TryRunHere(strand, pool, [&] { ran = true; }));
  EXPECT_FALSE(ran);
  busy.Release();
  // Every core busy with other sessions: not here, and the strand is left free.
  const auto other = std::make_shared<SessionStrand>();
  TaskInFlight first(other, pool);
  const auto third = std::make_shared<SessionStrand>();
  TaskInFlight second(third, pool);
  EXPECT_FALSE(SessionStrand::TryRunHere(strand, pool, [&] { ran = true; }));
  EXPECT_FALSE(ran);
  first.Release();
  second.Release();
  pool.Shutdown();
  EXPECT_EQ(strand->waiting(), 0);
  EXPECT_TRUE(SessionStrand::RunNowIfIdle(strand, pool, [] {}));  // not left marked busy
}

TEST(SessionStrand, TasksSubmittedDuringARunHereFollowIt) {
  WorkerPool pool(2, 8);
  const auto strand = std::make_shared<SessionStrand>();
  std::mutex mu;
  std::vector<int> order;
  std::promise<void> second_ran;
  EXPECT_TRUE(SessionStrand::TryRunHere(strand, pool, [&] {
    EXPECT_TRUE(SessionStrand::Submit(strand, pool, Task([&] {
                                        std::lock_guard<std::mutex> lock(mu);
                                        order.push_back(2);
                                        second_ran.set_value();
                                      }))
                    .ok());
    std::this_thread::sleep_for(20ms);  // the submitted task must wait for this one, however long it runs
    std::lock_guard<std::mutex> lock(mu);
    order.push_back(1);
  }));
  ASSERT_EQ(second_ran.get_future().wait_for(30s), std::future_status::ready);
  std::lock_guard<std::mutex> lock(mu);
  EXPECT_THAT(order, ::testing::ElementsAre(1, 2));
}

}  // namespace
}  // namespace nupmpc::server
