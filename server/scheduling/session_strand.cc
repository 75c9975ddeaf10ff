#include "server/scheduling/session_strand.h"

#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {

absl::Status SessionStrand::Submit(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool, Task task) {
  {
    std::unique_lock<std::mutex> lock(strand->mu_);
    if (strand->busy_) {
      std::vector<Task> superseded;
      for (auto it = strand->waiting_.begin(); it != strand->waiting_.end();) {
        if (it->superseded && it->superseded()) {
          superseded.push_back(std::move(*it));
          it = strand->waiting_.erase(it);
        } else {
          ++it;
        }
      }
      absl::Status queued = absl::OkStatus();
      if (static_cast<int>(strand->waiting_.size()) >= kMaxWaiting) {
        queued = absl::ResourceExhaustedError(absl::StrCat(
            "session_id: ", kMaxWaiting, " solves already wait for this session; send the next one after an answer"));
      } else {
        strand->waiting_.push_back(std::move(task));
      }
      lock.unlock();
      // Outside the lock: an answer may finish a call, whose end may submit again.
      for (Task& t : superseded) t.answer_superseded();
      return queued;
    }
    strand->busy_ = true;
  }
  absl::Status started = Start(strand, pool, std::move(task));
  if (!started.ok()) StartNext(strand, pool);  // tasks may have queued up behind the refused one
  return started;
}

absl::Status SessionStrand::Start(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool, Task task) {
  auto run = std::move(task.run);
  return pool.TrySubmit(
      [strand, &pool, run = std::move(run)]() mutable {
        run();
        run = nullptr;  // release the call's state before the next task starts
        StartNext(strand, pool);
      },
      task.expected_ms, task.placement, task.due);
}

void SessionStrand::StartNext(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool) {
  for (;;) {
    Task next;
    {
      std::lock_guard<std::mutex> lock(strand->mu_);
      if (strand->waiting_.empty()) {
        strand->busy_ = false;
        return;
      }
      next = std::move(strand->waiting_.front());
      strand->waiting_.pop_front();
    }
    auto fail = std::move(next.fail);
    const absl::Status started = Start(strand, pool, std::move(next));
    if (started.ok()) return;
    fail(started);  // e.g. the pool is full or shutting down: answer it, try the next
  }
}

bool SessionStrand::TryRunHere(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool,
                               const std::function<void()>& run, const std::function<void()>& then, double drain_ms) {
  {
    std::lock_guard<std::mutex> lock(strand->mu_);
    if (strand->busy_) return false;
    strand->busy_ = true;
  }
  const bool ran = pool.TryRunHere(
      [&] {
        try {
          run();
        } catch (...) {
          StartNext(strand, pool);  // the session stays usable whatever the task did
          throw;
        }
        StartNext(strand, pool);  // tasks that queued up for the session meanwhile
        if (then) then();
      },
      drain_ms);
  if (!ran) StartNext(strand, pool);  // frees the strand
  return ran;
}

bool SessionStrand::RunNowIfIdle(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool,
                                 const std::function<void()>& work) {
  {
    std::lock_guard<std::mutex> lock(strand->mu_);
    if (strand->busy_) return false;
    strand->busy_ = true;
  }
  work();
  StartNext(strand, pool);  // tasks may have queued up while it ran
  return true;
}

void SessionStrand::RunExclusive(const std::shared_ptr<SessionStrand>& strand, WorkerPool& pool,
                                 const std::function<void()>& work) {
  {
    std::lock_guard<std::mutex> lock(strand->mu_);
    if (strand->busy_) {
      // StartNext calls `fail` with the strand still held, so the work is exclusive either way.
      strand->waiting_.push_front({.run = work, .fail = [work](const absl::Status&) { work(); }, .expected_ms = 0.0});
      return;
    }
    strand->busy_ = true;
  }
  work();
  StartNext(strand, pool);
}

int SessionStrand::waiting() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int>(waiting_.size());
}

}  // namespace nupmpc::server
