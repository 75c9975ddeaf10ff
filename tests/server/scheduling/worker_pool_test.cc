// The worker pool's admission: a bounded queue, and a bound on the estimated wait built
// from each queued task's expected duration; refused work is RESOURCE_EXHAUSTED.
#include "server/scheduling/worker_pool.h"

#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/state/server_state.h"

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
                    })
                    .ok());
    started_.get_future().wait();
  }
  void Release() { release_.set_value(); }

 private:
  std::promise<void> started_, release_;
};

// The order queued tasks run in, on one worker held busy while they are queued.
std::vector<int> RunOrder(WorkerPool::Scheduling scheduling,
                          const std::vector<std::optional<std::chrono::milliseconds>>& due_in) {
  WorkerPool pool(1, 64, 0.0, 0, scheduling);
  std::vector<int> order;
  std::mutex mu;
  {
    Blocker blocker(pool);
    const auto now = WorkerPool::Clock::now();
    for (int i = 0; i < static_cast<int>(due_in.size()); ++i) {
      std::optional<WorkerPool::Clock::time_point> due;
      if (due_in[i].has_value()) due = now + *due_in[i];
      EXPECT_TRUE(pool.TrySubmit(
                          [&, i] {
                            std::lock_guard<std::mutex> lock(mu);
                            order.push_back(i);
                          },
                          -1.0, WorkerPool::Placement::kWorker, due)
                      .ok());
    }
    blocker.Release();
  }
  pool.Shutdown();
  return order;
}

TEST(WorkerPool, TakesQueuedTasksEarliestDeadlineFirst) {
  using std::chrono::milliseconds;
  // Deadlines in 30, 10, 20 ms, then one without a deadline (due 1 s after it arrived) and
  // one due in 2 s: the undated one goes before the late deadline, after the near ones.
  EXPECT_THAT(RunOrder(WorkerPool::Scheduling::kEarliestDeadlineFirst,
                       {milliseconds(30), milliseconds(10), milliseconds(20), std::nullopt, milliseconds(2000)}),
              ::testing::ElementsAre(1, 2, 0, 3, 4));
  // Equal deadlines and undated tasks keep their arrival order.
  EXPECT_THAT(RunOrder(WorkerPool::Scheduling::kEarliestDeadlineFirst,
                       {std::nullopt, milliseconds(50), std::nullopt, milliseconds(50)}),
              ::testing::ElementsAre(1, 3, 0, 2));
}

TEST(WorkerPool, FifoSchedulingIgnoresDeadlines) {
  using std::chrono::milliseconds;
  EXPECT_THAT(RunOrder(WorkerPool::Scheduling::kFifo,
                       {milliseconds(30), milliseconds(10), milliseconds(20), std::nullopt, milliseconds(2000)}),
              ::testing::ElementsAre(0, 1, 2, 3, 4));
}

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

TEST(WorkerPool, TheWaitEstimateSharesTheQueueAmongTheWorkersNotTheCores) {
  // Queued work waits for the workers; cores beyond them belong to callers that come and go.
  WorkerPool pool(1, 100, /*max_queue_wait_ms=*/25.0, /*cores=*/2);
  Blocker blocker(pool);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(pool.TrySubmit([] {}, 10.0).ok()) << i;
  EXPECT_EQ(pool.TrySubmit([] {}, 10.0).code(), absl::StatusCode::kResourceExhausted);
  blocker.Release();
}

TEST(WorkerPool, WithoutAWaitBoundOnlyTheCapacityCounts) {
  WorkerPool pool(1, 100);
  Blocker blocker(pool);
  for (int i = 0; i < 50; ++i) EXPECT_TRUE(pool.TrySubmit([] {}, 1000.0).ok()) << i;
  blocker.Release();
}

// The hand-off's cost is measured on tasks handed to an idle worker, and only on those: a
// task that waited behind another one would count its queueing as hand-off.
TEST(WorkerPool, MeasuresTheHandOffToAnIdleWorkerOnly) {
  WorkerPool pool(1, 8);
  EXPECT_EQ(pool.handoff_ms(), 0.0) << "nothing handed over yet";
  for (int i = 0; i < 5; ++i) {
    std::promise<void> ran;
    ASSERT_TRUE(pool.TrySubmit([&ran] { ran.set_value(); }).ok());
    ran.get_future().wait();
    // Until the worker has given its core back the next task would find it busy.
    while (pool.busy() > 0) std::this_thread::yield();
  }
  const double measured = pool.handoff_ms();
  EXPECT_GT(measured, 0.0);
  // A task queued behind a 500 ms one waits 500 ms for the worker: not a hand-off (counted,
  // it would raise the weighted average by at least 50 ms).
  Blocker blocker(pool);
  std::promise<void> queued_ran;
  ASSERT_TRUE(pool.TrySubmit([&queued_ran] { queued_ran.set_value(); }).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  blocker.Release();
  queued_ran.get_future().wait();
  EXPECT_LT(pool.handoff_ms(), measured + 20.0) << "the queued task's wait was counted";
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
  const std::shared_future<void> queued_done = queued_ran.get_future().share();
  ASSERT_TRUE(queued_pool.TrySubmit([&] { queued_ran.set_value(); }).ok());
  blocker.Release();
  // Whether or not the worker has taken the queued task yet, it is not overtaken: either
  // it is still queued (refused here) or it holds the only core, or it is done.
  bool overtook = false;
  (void)queued_pool.TryRunHere(
      [&] { overtook = queued_done.wait_for(std::chrono::seconds(0)) != std::future_status::ready; });
  EXPECT_FALSE(overtook);
  EXPECT_EQ(queued_done.wait_for(std::chrono::seconds(30)), std::future_status::ready);
}

TEST(WorkerPool, CoresBeyondItsWorkersAreForCallersAndStillBoundWhatRunsAtOnce) {
  // One worker, two cores (a server whose gRPC has two reaction threads on one core).
  WorkerPool pool(1, 4, /*max_queue_wait_ms=*/0.0, /*cores=*/2);
  EXPECT_EQ(pool.threads(), 1);
  EXPECT_EQ(pool.cores(), 2);
  Blocker blocker(pool);  // the worker's task holds one core
  bool second_ran = false;
  bool third_ran = false;
  EXPECT_TRUE(pool.TryRunHere([&] {
    second_ran = true;
    // Worker and this caller hold both cores: a third solve may not start anywhere.
    std::thread other([&] { EXPECT_FALSE(pool.TryRunHere([&] { third_ran = true; })); });
    other.join();
  }));
  EXPECT_TRUE(second_ran);
  EXPECT_FALSE(third_ran);
  blocker.Release();
  pool.Shutdown();
  EXPECT_EQ(pool.busy(), 0);
  EXPECT_EQ(WorkerPool(2, 4, 0.0, /*cores=*/1).cores(), 2);  // never fewer cores than workers
}

TEST(WorkerPool, ACoreHolderDrainsPastItsBudgetWhileNoWorkerIsFreeToTakeOver) {
  // One worker busy with long work, a second core held here: short steps queued behind
  // this one would otherwise wait for the long task while this core stood idle.
  WorkerPool pool(1, 8, /*max_queue_wait_ms=*/0.0, /*cores=*/2);
  Blocker blocker(pool);
  std::atomic<int> ran{0};
  EXPECT_TRUE(pool.TryRunHere(
      [&] {
        for (int i = 0; i < 3; ++i) {
          ASSERT_TRUE(pool.TrySubmit(
                              [&] {
                                std::this_thread::sleep_for(std::chrono::milliseconds(2));  // past the budget
                                ++ran;
                              },
                              0.1, WorkerPool::Placement::kAnyCoreHolder)
                          .ok());
        }
      },
      /*drain_ms=*/1.0));
  EXPECT_EQ(ran.load(), 3);
  EXPECT_EQ(pool.queued(), 0);
  blocker.Release();
}

TEST(WorkerPool, ACoreHolderStopsAtItsBudgetWhileTheWorkerRunsShortTasks) {
  // One worker and two cores, short steps arriving without pause: the worker takes them as
  // well, so the thread holding the second core must go back (to gRPC, to serve its own
  // stream) at its budget, not drain for as long as steps keep coming (a Control stream
  // whose reaction drained went unanswered for seconds at 64 streams).
  WorkerPool pool(1, 64, /*max_queue_wait_ms=*/0.0, /*cores=*/2);
  std::atomic<bool> holder_returned{false};
  std::atomic<bool> feeding{true};
  std::thread feeder;
  const auto short_step = [] { std::this_thread::sleep_for(std::chrono::microseconds(200)); };
  EXPECT_TRUE(pool.TryRunHere(
      [&] {
        feeder = std::thread([&] {
          const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(3);
          while (!holder_returned.load() && std::chrono::steady_clock::now() < give_up) {
            // The queue kept full (the rest refused): the worker never waits for work.
            (void)pool.TrySubmit(short_step, 0.2, WorkerPool::Placement::kAnyCoreHolder);
          }
          feeding.store(false);
        });
        std::this_thread::sleep_for(std::chrono::milliseconds(5));  // a queue behind this step
      },
      /*drain_ms=*/1.0));
  const bool fed_throughout = feeding.load();
  holder_returned.store(true);
  feeder.join();
  EXPECT_TRUE(fed_throughout) << "the holder drained until the steps stopped coming";
  pool.Shutdown();
}

TEST(SolverCores, AtLeastGrpcsReactionThreadsWhenStepsAreSolvedOnThem) {
  ServerOptions o;
  o.worker_threads = 1;
  o.inline_solve_max_ms = 0.5;
  EXPECT_EQ(SolverCores(o), kGrpcReactionThreadsAtLeast);
  o.inline_solve_max_ms = 0.0;  // every solve on a worker: the workers are the bound
  EXPECT_EQ(SolverCores(o), 1);
  o.worker_threads = 4;
  o.inline_solve_max_ms = 0.5;
  EXPECT_EQ(SolverCores(o), 4);
}

TEST(SolverCores, TheServerReportsThemInItsLimits) {
  for (const double inline_ms : {0.5, 0.0}) {
    ServerOptions o;
    o.worker_threads = 1;
    o.inline_solve_max_ms = inline_ms;
    const ServerState state(o);
    v1::ServerLimits limits;
    state.FillLimits(&limits);
    EXPECT_EQ(limits.worker_threads(), 1u);
    EXPECT_EQ(limits.solver_cores(), static_cast<std::uint32_t>(SolverCores(o))) << "inline_solve_max_ms " << inline_ms;
    EXPECT_EQ(static_cast<int>(limits.solver_cores()), state.pool.cores());
  }
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

TEST(WorkerPool, ACoreHolderRunsTheShortTasksQueuedBehindItThenLeavesTheRestToWorkers) {
  WorkerPool pool(1, 8);
  std::mutex mu;
  std::vector<std::pair<int, std::thread::id>> ran;
  std::promise<void> workers_done;
  const auto record = [&](int i) {
    std::lock_guard<std::mutex> lock(mu);
    ran.emplace_back(i, std::this_thread::get_id());
  };
  using Placement = WorkerPool::Placement;
  EXPECT_TRUE(pool.TryRunHere(
      [&] {
        // Queued while this thread holds the only core: no worker may start them.
        for (int i = 0; i < 3; ++i)
          ASSERT_TRUE(pool.TrySubmit([&, i] { record(i); }, 0.1, Placement::kAnyCoreHolder).ok());
        ASSERT_TRUE(pool.TrySubmit([&] { record(3); }, 0.1, Placement::kWorker).ok());
        ASSERT_TRUE(pool.TrySubmit(
                            [&] {
                              record(4);
                              workers_done.set_value();
                            },
                            0.1, Placement::kAnyCoreHolder)
                        .ok());
      },
      /*drain_ms=*/10000.0));
  ASSERT_EQ(workers_done.get_future().wait_for(std::chrono::seconds(30)), std::future_status::ready);
  std::lock_guard<std::mutex> lock(mu);
  ASSERT_EQ(ran.size(), 5u);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(ran[i].first, i);  // in the order they were queued
  // The short tasks at the front ran here; from the first worker-only task on, a worker.
  for (int i = 0; i < 3; ++i) EXPECT_EQ(ran[i].second, std::this_thread::get_id()) << i;
  for (int i = 3; i < 5; ++i) EXPECT_NE(ran[i].second, std::this_thread::get_id()) << i;
  EXPECT_EQ(pool.run_here(), 4u);  // its own task and three queued ones
}

TEST(WorkerPool, ACoreHolderThatFindsTheQueueEmptyGivesTheCoreBackBeforeReturning) {
  WorkerPool pool(1, 8);
  EXPECT_TRUE(pool.TryRunHere(
      [&] { ASSERT_TRUE(pool.TrySubmit([] {}, 0.1, WorkerPool::Placement::kAnyCoreHolder).ok()); }, 10000.0));
  // Nothing left for a worker, and the core is free at once for the next arrival.
  EXPECT_EQ(pool.queued(), 0);
  EXPECT_EQ(pool.busy(), 0);
  EXPECT_TRUE(pool.TryRunHere([] {}));
  EXPECT_EQ(pool.run_here(), 3u);
}

TEST(WorkerPool, ACallerWaitsForACoreRunningShortWorkAndTakesOverTheQueue) {
  using Placement = WorkerPool::Placement;
  WorkerPool pool(1, 8);
  std::promise<void> started, release;
  std::shared_future<void> released = release.get_future().share();
  ASSERT_TRUE(pool.TrySubmit(
                      [&started, released] {
                        started.set_value();
                        released.wait();
                      },
                      0.1, Placement::kAnyCoreHolder)
                  .ok());
  started.get_future().wait();  // a worker runs short work on the only core
  std::thread::id queued_ran_on;
  ASSERT_TRUE(pool.TrySubmit([&] { queued_ran_on = std::this_thread::get_id(); }, 0.1, Placement::kAnyCoreHolder).ok());
  std::thread releaser([&] {
    // Ends the worker's task once the caller waits for the core (a caller that did not
    // wait would have been refused by then), or after 30 s, which fails the test.
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (pool.callers_waiting() == 0 && std::chrono::steady_clock::now() < give_up) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    release.set_value();
  });
  std::thread::id ran_on;
  EXPECT_TRUE(pool.TryRunHere([&] { ran_on = std::this_thread::get_id(); }, /*drain_ms=*/60000.0));
  releaser.join();
  // The core the worker gave back came here, and so did the short task queued before.
  EXPECT_EQ(ran_on, std::this_thread::get_id());
  EXPECT_EQ(queued_ran_on, std::this_thread::get_id());
  EXPECT_EQ(pool.queued(), 0);
}

TEST(WorkerPool, ACallerDoesNotWaitForACoreAnotherCallerHoldsButQueuesForIt) {
  WorkerPool pool(1, 8);
  std::promise<void> holding, release;
  std::thread::id holder_id, queued_ran_on;
  std::thread holder([&] {
    holder_id = std::this_thread::get_id();
    EXPECT_TRUE(pool.TryRunHere(
        [&] {
          holding.set_value();
          release.get_future().wait();
        },
        /*drain_ms=*/60000.0));
  });
  holding.get_future().wait();
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(pool.TryRunHere([] {}, /*drain_ms=*/60000.0));
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(30));  // refused at once
  // What it queues instead is run by the holder, not a worker.
  ASSERT_TRUE(
      pool.TrySubmit([&] { queued_ran_on = std::this_thread::get_id(); }, 0.1, WorkerPool::Placement::kAnyCoreHolder)
          .ok());
  release.set_value();
  holder.join();
  EXPECT_EQ(queued_ran_on, holder_id);
}

TEST(WorkerPool, ACallerDoesNotWaitForACoreRunningWorkMeantForWorkers) {
  WorkerPool pool(1, 8);
  Blocker blocker(pool);  // kWorker: of unknown length
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(pool.TryRunHere([] {}, /*drain_ms=*/60000.0));
  // Refused at once, not after the minute it would have waited.
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(30));
  blocker.Release();
}

TEST(WorkerPool, ATaskThatThrowsHereGivesItsCoreBack) {
  WorkerPool pool(1, 4);
  EXPECT_THROW(pool.TryRunHere([] { throw std::runtime_error("escaped"); }), std::runtime_error);
  std::promise<void> ran;
  ASSERT_TRUE(pool.TrySubmit([&] { ran.set_value(); }).ok());
  EXPECT_EQ(ran.get_future().wait_for(std::chrono::seconds(30)), std::future_status::ready);
  // The worker gives its core back just after the task's last statement.
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  bool ran_here = false;
  while (!(ran_here = pool.TryRunHere([] {})) && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_TRUE(ran_here);
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
