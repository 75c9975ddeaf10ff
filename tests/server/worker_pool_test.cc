// The worker pool's admission: a bounded queue, and a bound on the estimated wait built
// from each queued task's expected duration; refused work is RESOURCE_EXHAUSTED.
#include "server/worker_pool.h"

#include <atomic>
#include <future>
#include <stdexcept>
#include <thread>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

// Occupies the pool's only thread until released. The task holds its own copy of the
// release future: it may still be waking up when a test has released it and the Blocker
// is gone (ASan: stack-use-after-scope when the task called release_.get_future() late).
class Blocker {
 public:
  explicit Blocker(WorkerPool& pool) {
    EXPECT_TRUE(pool.TrySubmit([this, released = release_.get_future().share()] {
                      started_.set_value();  // the constructor is still waiting: `this` lives
                      released.wait();
                    }).ok());
    started_.get_future().wait();
  }
  void Release() { release_.set_value(); }

 private:
  std::promise<void> started_, release_;
};

TEST(WorkerPool, RefusesWorkBeyondTheQueueCapacity) {
  WorkerPool pool(1, 2);
  Blocker blocker(pool);
  std::atomic<int> ran{0};
  EXPECT_TRUE(pool.TrySubmit([&] { ++ran; }).ok());
  EXPECT_TRUE(pool.TrySubmit([&] { ++ran; }).ok());
  const absl::Status third = pool.TrySubmit([&] { ++ran; });
  EXPECT_EQ(third.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(third.message()), ::testing::HasSubstr("queue is full"));
  blocker.Release();
  pool.Shutdown();  // runs what was queued
  EXPECT_EQ(ran.load(), 2);
}

TEST(WorkerPool, RefusesWorkTheQueuedSolvesWouldDelayTooLong) {
  WorkerPool pool(1, 100, /*max_queue_wait_ms=*/25.0);
  Blocker blocker(pool);
  // Queued ahead: 0, 10, 20 ms (all within 25 ms), then 30 ms: refused.
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(pool.TrySubmit([] {}, 10.0).ok()) << i;
  const absl::Status refused = pool.TrySubmit([] {}, 10.0);
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(refused.message()), ::testing::HasSubstr("max_queue_wait_ms"));
  blocker.Release();
  pool.Shutdown();
  EXPECT_EQ(pool.TrySubmit([] {}).code(), absl::StatusCode::kUnavailable);
}

TEST(WorkerPool, WithoutAWaitBoundOnlyTheCapacityCounts) {
  WorkerPool pool(1, 100);
  Blocker blocker(pool);
  for (int i = 0; i < 50; ++i) EXPECT_TRUE(pool.TrySubmit([] {}, 1000.0).ok()) << i;
  blocker.Release();
}

TEST(WorkerPool, RunsATaskHereWhenACoreIsFree) {
  WorkerPool pool(2, 4);
  std::thread::id ran_on;
  EXPECT_TRUE(pool.TryRunHere([&] { ran_on = std::this_thread::get_id(); }));
  EXPECT_EQ(ran_on, std::this_thread::get_id());
  EXPECT_EQ(pool.run_here(), 1u);
  // One core taken by a worker's task: the other is still free.
  Blocker blocker(pool);
  EXPECT_TRUE(pool.TryRunHere([] {}));
  blocker.Release();
}

TEST(WorkerPool, RunsNothingHereWhileEveryCoreIsBusyOrWorkIsQueued) {
  WorkerPool pool(1, 4);
  {
    Blocker blocker(pool);
    bool ran = false;
    EXPECT_FALSE(pool.TryRunHere([&] { ran = true; }));  // the only core runs the blocker
    EXPECT_FALSE(ran);
    blocker.Release();
  }
  pool.Shutdown();
  WorkerPool queued_pool(1, 4);
  Blocker blocker(queued_pool);
  std::promise<void> queued_ran;
  ASSERT_TRUE(queued_pool.TrySubmit([&] { queued_ran.set_value(); }).ok());
  blocker.Release();
  // Whether or not the worker has taken the queued task yet, it is not overtaken: either
  // it is still queued (refused here) or it holds the only core.
  bool overtook = false;
  (void)queued_pool.TryRunHere([&] { overtook = queued_ran.get_future().wait_for(std::chrono::seconds(0)) !=
                                                std::future_status::ready; });
  EXPECT_FALSE(overtook);
  EXPECT_EQ(queued_ran.get_future().wait_for(std::chrono::seconds(30)), std::future_status::ready);
}

TEST(WorkerPool, WorkersWaitForTheCoreATaskRunningHereHolds) {
  // One core: while a task runs on this thread, a submitted task must not start on the
  // worker (two solves would share one core); it starts once this one is done.
  WorkerPool pool(1, 4);
  std::atomic<bool> here_done{false};
  std::promise<bool> started_after;
  EXPECT_TRUE(pool.TryRunHere([&] {
    ASSERT_TRUE(pool.TrySubmit([&] { started_after.set_value(here_done.load()); }).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(50));  // time for a worker that would wrongly start
    here_done.store(true);
  }));
  std::future<bool> result = started_after.get_future();
  ASSERT_EQ(result.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  EXPECT_TRUE(result.get());
  pool.Shutdown();  // the worker gives its core back after the task's last statement
  EXPECT_EQ(pool.busy(), 0);
}

TEST(WorkerPool, ATaskThatThrowsHereGivesItsCoreBack) {
  WorkerPool pool(1, 4);
  EXPECT_THROW(pool.TryRunHere([] { throw std::runtime_error("escaped"); }), std::runtime_error);
  std::promise<void> ran;
  ASSERT_TRUE(pool.TrySubmit([&] { ran.set_value(); }).ok());
  EXPECT_EQ(ran.get_future().wait_for(std::chrono::seconds(30)), std::future_status::ready);
  EXPECT_TRUE(pool.TryRunHere([] {}));
}

}  // namespace
}  // namespace nupmpc::server

namespace nupmpc::server {
namespace {

TEST(WorkerPool, ATaskThatThrowsDoesNotTakeItsWorkerWithIt) {
  WorkerPool pool(1, 4);
  ASSERT_TRUE(pool.TrySubmit([] { throw std::runtime_error("escaped"); }).ok());
  std::promise<void> ran;
  ASSERT_TRUE(pool.TrySubmit([&] { ran.set_value(); }).ok());
  EXPECT_EQ(ran.get_future().wait_for(std::chrono::seconds(30)), std::future_status::ready);
}

}  // namespace
}  // namespace nupmpc::server
