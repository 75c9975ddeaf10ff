#ifndef NUPMPC_SERVER_SCHEDULING_SESSION_STRAND_H_
#define NUPMPC_SERVER_SCHEDULING_SESSION_STRAND_H_

#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>

#include "absl/status/status.h"
#include "server/scheduling/worker_pool.h"

namespace nupmpc::server {

// One session's work, run one task at a time on the worker pool without a worker ever
// waiting for the session: while a task of the session is queued or running, later ones
// wait here and are handed to the pool when it finishes. Two unary Solves on one session
// thus occupy at most one worker (a lock would hold the second worker idle), and the
// other sessions keep the rest of the pool.
//
// The strand is the session's only serialiser: solves, idle compaction and closing all
// run as its tasks, so whatever runs a task has the session to itself.
class SessionStrand {
 public:
  // Solves that may wait for one session; more are refused (RESOURCE_EXHAUSTED).
  static constexpr int kMaxWaiting = 16;

  struct Task {
    std::function<void()> run;               ///< runs on a worker, once
    std::function<void(absl::Status)> fail;  ///< answers the call if the pool refuses it later
    double expected_ms = -1.0;               ///< for the pool's admission (WorkerPool::TrySubmit)
    WorkerPool::Placement placement = WorkerPool::Placement::kWorker;
    std::optional<WorkerPool::Clock::time_point> due = std::nullopt;  ///< its answer's deadline (the pool's order)
    // Steps that a newer one of the session replaces (SolveFleet's "newest state wins"):
    // whether a newer step has been accepted since, and how this one is then answered
    // without running. Each Submit removes the waiting tasks that say so first, so stale
    // steps never hold the session's waiting places (or get the newest one refused).
    std::function<bool()> superseded = nullptr;
    std::function<void()> answer_superseded = nullptr;
  };

  // OK: the task will run (or, if the pool refuses it once it is its turn, fail, or, if it
  // is superseded while it waits, be answered so) exactly once. Otherwise it was not taken
  // and the caller answers with the status: the pool's refusal, or RESOURCE_EXHAUSTED when
  // kMaxWaiting tasks (none of them superseded) already wait for this session.
  static absl::Status Submit(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool, Task task);

  // Runs `run` now on the calling thread, as the session's next task, if no task of this
  // session is queued or running and the pool has a core free (WorkerPool::TryRunHere);
  // returns whether it ran. When it did not, nothing happened and the caller submits it.
  // After `run`, with the session given back but the core still held: `then` (if any),
  // then up to `drain_ms` of queued short tasks (WorkerPool::TryRunHere).
  static bool TryRunHere(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool,
                         const std::function<void()>& run, const std::function<void()>& then = nullptr,
                         double drain_ms = 0.0);
  // Runs `work` now, on the calling thread, if no task of this session is queued or
  // running, and returns true; else returns false and does nothing. For short work that
  // may be skipped while the session is busy (idle compaction).
  static bool RunNowIfIdle(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool,
                           const std::function<void()>& work);
  // Runs `work` with the session to itself and never refuses it: now on the calling thread
  // if the strand is idle, else right after the task in flight, before those that wait (on
  // a worker, or on the thread that finds the pool refusing it). For short work that must
  // happen (closing a session: the waiting solves then find it closed).
  static void RunExclusive(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool,
                           const std::function<void()>& work);

  int waiting() const;

 private:
  // Hands `task` to the pool; when it has run, the next waiting task follows.
  static absl::Status Start(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool, Task task);
  static void StartNext(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool);

  mutable std::mutex mu_;
  bool busy_ = false;  ///< a task of this session is in the pool (queued or running)
  std::deque<Task> waiting_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SCHEDULING_SESSION_STRAND_H_
