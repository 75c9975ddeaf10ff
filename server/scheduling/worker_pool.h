#ifndef NUPMPC_SERVER_SCHEDULING_WORKER_POOL_H_
#define NUPMPC_SERVER_SCHEDULING_WORKER_POOL_H_

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "absl/status/status.h"

namespace nupmpc::server {

// A fixed set of solver threads with a bounded queue. Solves are CPU-bound: the pool is
// sized to the cores the server may use (two by design), and work it cannot start soon is
// refused (RESOURCE_EXHAUSTED) instead of growing latency without bound: when the queue
// holds `queue_capacity` tasks, or (if `max_queue_wait_ms` > 0) when the work already
// queued would keep a new task waiting longer than that. The wait is estimated from each
// queued task's expected duration (a session's last solve time), so sessions of very
// different sizes are weighed correctly.
//
// The pool's size is a number of cores, not only of threads: a short task may run on the
// thread that has it (TryRunHere, e.g. a gRPC reaction solving a 0.1 ms step where it
// arrived, without the two thread switches of a hand-off), and it then holds one of the
// pool's cores() (the workers, or more: ServerState's SolverCores); workers start a queued
// task only while fewer than cores() tasks run in all. So the solves running at once never
// exceed the cores the pool was sized for.
//
// Queued tasks are taken earliest deadline first (a step's answer is due at its deadline,
// server/sessions/step_deadline.h): on one core EDF meets every deadline any order would.
// Work without a deadline (unary calls, steps of sessions without a period) counts as due
// kNoDeadlineGrace after it arrived, so it yields to steps due sooner but is never starved;
// among equal deadlines, arrival order. Scheduling::kFifo takes tasks by arrival alone (the
// load test compares the two).
class WorkerPool {
 public:
  using Clock = std::chrono::steady_clock;
  enum class Scheduling { kEarliestDeadlineFirst, kFifo };
  static constexpr std::chrono::milliseconds kNoDeadlineGrace{1000};

  // `cores` (at least `threads`; 0: `threads`): solves that may run at once, on workers and
  // on TryRunHere callers together.
  WorkerPool(int threads, int queue_capacity, double max_queue_wait_ms = 0.0, int cores = 0,
             Scheduling scheduling = Scheduling::kEarliestDeadlineFirst);
  ~WorkerPool();  // Shutdown()
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Where a queued task may run: only on a worker, or also on a thread that holds a core
  // through TryRunHere (a short task: it holds that thread about as long as the one before).
  enum class Placement { kWorker, kAnyCoreHolder };

  // Queues a task expected to run `expected_ms` (negative: unknown, the recent average of
  // the pool's tasks is used), due at `due` (none: see the class comment).
  // RESOURCE_EXHAUSTED when refused as above, UNAVAILABLE when the pool is shut down.
  absl::Status TrySubmit(std::function<void()> task, double expected_ms = -1.0,
                         Placement placement = Placement::kWorker, std::optional<Clock::time_point> due = {});
  // Runs `task` now on the calling thread and returns true if a core is free for it (fewer
  // than cores() tasks run) and nothing is queued (queued tasks go first); else returns
  // false without running it. With `drain_ms` > 0, the thread that holds a core also
  // runs the queued tasks submitted as kAnyCoreHolder, oldest first, while they are at
  // the front of the queue, for up to `drain_ms` (before `task` those queued before it,
  // after it those queued meanwhile; past `drain_ms` only while every worker runs a long
  // task, as can happen with more cores than workers); and when every core runs such short work on a
  // worker, it waits up to `drain_ms` for one (workers step aside for it). Steps that
  // arrive while a core is busy are then taken by the thread that has it instead of
  // handed to a worker one by one. Counted in busy() and busy_seconds() like the workers' tasks.
  bool TryRunHere(const std::function<void()>& task, double drain_ms = 0.0);
  // Stops accepting, runs what is queued, joins the threads. Idempotent.
  void Shutdown();

  int threads() const { return threads_started_; }
  int cores() const { return cores_; }
  int queue_capacity() const { return capacity_; }
  Scheduling scheduling() const { return scheduling_; }
  int queued() const;
  // Callers of TryRunHere waiting for a core now.
  int callers_waiting() const;
  // Tasks run on a caller's thread by TryRunHere since start, its own and queued ones.
  std::uint64_t run_here() const { return run_here_.load(std::memory_order_relaxed); }
  // For the metrics: tasks running now (on workers and callers), and the seconds all of them
  // spent running since start (its rate over cores() is the pool's utilisation).
  int busy() const { return busy_.load(std::memory_order_relaxed); }
  double busy_seconds() const { return busy_seconds_.load(std::memory_order_relaxed); }
  // What handing a task to an idle worker costs on this machine: from TrySubmit to the
  // worker starting it, for tasks that found a core free and nothing queued (so the wait
  // is the wake-up and the thread switch alone), exponentially weighted; 0 until measured.
  double handoff_ms() const { return handoff_ms_.load(std::memory_order_relaxed); }

 private:
  struct Task {
    std::function<void()> run;
    double expected_ms = 0.0;
    Placement placement = Placement::kWorker;
    Clock::time_point order;  ///< the queue is sorted by this (stable): deadline, or arrival
    /// When it was submitted to a free core with nothing queued (handoff_ms measures it).
    std::optional<Clock::time_point> handed_to_idle_at;
  };
  // Where a task with `order` goes: after every queued task with an order not later.
  void InsertLocked(Task task);

  void Run();
  // Runs a queued task; a throwing task is logged, not propagated (it answers its own call).
  static void RunQueued(Task& task);
  // Runs the queued kAnyCoreHolder tasks at the front of the queue on this thread, which
  // holds a core, for up to `drain_ms`. With `release_when_empty`, gives the core back
  // when it finds the queue empty and returns true.
  bool RunQueuedHere(double drain_ms, bool release_when_empty);
  // Bookkeeping of a task that ran for `took_ms` (either kind); called without mu_.
  void Record(double took_ms);
  // Gives back the core a task held (a kWorker task: `long_task`; held by a TryRunHere
  // caller: `caller`): to a thread waiting in TryRunHere, else to a worker if work is
  // queued. Called without mu_.
  void ReleaseCore(bool long_task, bool caller);
  const int threads_started_;  ///< worker threads
  const int cores_;            ///< tasks that may run at once (workers' and callers')
  const int capacity_;
  const double max_queue_wait_ms_;
  const Scheduling scheduling_;
  mutable std::mutex mu_;
  std::condition_variable ready_;      ///< workers: work queued and a core free
  std::condition_variable core_free_;  ///< threads waiting in TryRunHere for a core
  std::deque<Task> queue_;
  double queued_ms_ = 0.0;        ///< sum of the queued tasks' expected_ms
  double average_task_ms_ = 0.0;  ///< exponentially weighted, of finished tasks
  bool stopping_ = false;
  int running_ = 0;       ///< tasks running, on workers or through TryRunHere (at most cores())
  int running_long_ = 0;  ///< of them, kWorker tasks (a caller does not wait for those)
  int running_here_ = 0;  ///< of them, held by TryRunHere callers
  int here_waiting_ = 0;  ///< callers of TryRunHere waiting for a core
  std::atomic<int> busy_{0};
  std::atomic<double> busy_seconds_{0.0};
  std::atomic<std::uint64_t> run_here_{0};
  std::atomic<double> handoff_ms_{0.0};
  std::vector<std::thread> threads_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SCHEDULING_WORKER_POOL_H_
