#include "server/scheduling/worker_pool.h"

#include <algorithm>
#include <chrono>
#include <exception>
#include <iterator>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {

WorkerPool::WorkerPool(int threads, int queue_capacity, double max_queue_wait_ms, int cores, Scheduling scheduling)
    : threads_started_(threads),
      cores_(std::max(cores, threads)),
      capacity_(queue_capacity),
      max_queue_wait_ms_(max_queue_wait_ms),
      scheduling_(scheduling) {
  threads_.reserve(threads);
  for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { Run(); });
}

WorkerPool::~WorkerPool() { Shutdown(); }

void WorkerPool::InsertLocked(Task task) {
  // From the back: most tasks arrive in order (no deadline, or one period ahead).
  auto at = queue_.end();
  while (at != queue_.begin() && std::prev(at)->order > task.order) --at;
  queue_.insert(at, std::move(task));
}

absl::Status WorkerPool::TrySubmit(std::function<void()> task, double expected_ms, Placement placement,
                                   std::optional<Clock::time_point> due) {
  bool wake;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return absl::UnavailableError("the server is shutting down");
    if (static_cast<int>(queue_.size()) >= capacity_) {
      return absl::ResourceExhaustedError(
          absl::StrCat("the solve queue is full (", capacity_, " waiting); retry later"));
    }
    const double wait_ms = queued_ms_ / static_cast<double>(threads_started_);
    if (max_queue_wait_ms_ > 0.0 && wait_ms > max_queue_wait_ms_) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "the solves queued ahead would take about %.3g ms, over the server's max_queue_wait_ms = %g; retry later",
          wait_ms, max_queue_wait_ms_));
    }
    if (expected_ms < 0.0) expected_ms = average_task_ms_;
    const Clock::time_point now = Clock::now();
    Clock::time_point order = now;
    if (scheduling_ == Scheduling::kEarliestDeadlineFirst) order = due.value_or(now + kNoDeadlineGrace);
    // With every core taken a woken worker would only go back to sleep; ReleaseCore wakes one.
    wake = running_ < cores_ && here_waiting_ == 0;
    std::optional<Clock::time_point> handed_to_idle_at;
    if (wake && queue_.empty() && running_ - running_here_ < threads_started_) handed_to_idle_at = now;
    InsertLocked(Task{std::move(task), expected_ms, placement, order, handed_to_idle_at});
    queued_ms_ += expected_ms;
  }
  if (wake) ready_.notify_one();
  return absl::OkStatus();
}

int WorkerPool::queued() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int>(queue_.size());
}

int WorkerPool::callers_waiting() const {
  std::lock_guard<std::mutex> lock(mu_);
  return here_waiting_;
}

void WorkerPool::Shutdown() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_ && threads_.empty()) return;
    stopping_ = true;
  }
  ready_.notify_all();
  core_free_.notify_all();
  for (std::thread& t : threads_) {
    if (t.joinable()) t.join();
  }
  threads_.clear();
}

bool WorkerPool::TryRunHere(const std::function<void()>& task, double drain_ms) {
  {
    std::unique_lock<std::mutex> lock(mu_);
    if (drain_ms > 0.0 && !stopping_ && running_ >= cores_ && running_long_ == 0 && running_here_ == 0) {
      // Every core runs a short task on a worker: the next to end gives its core to this
      // thread (workers step aside while one waits), which then also runs what queued
      // meanwhile, instead of a worker handing those steps over one by one. (A core held
      // by a caller is not waited for: that caller runs what is queued behind it, so this
      // thread is better off going back to gRPC to read the next request.)
      ++here_waiting_;
      core_free_.wait_for(lock, std::chrono::duration<double, std::milli>(drain_ms),
                          [this] { return stopping_ || running_ < cores_; });
      --here_waiting_;
    }
    if (stopping_ || running_ >= cores_) return false;
    if (!queue_.empty() && (drain_ms <= 0.0 || queue_.front().placement != Placement::kAnyCoreHolder)) {
      if (here_waiting_ == 0) ready_.notify_one();  // it is a worker's, and this core is free
      return false;
    }
    ++running_;
    ++running_here_;
  }
  busy_.fetch_add(1, std::memory_order_relaxed);
  // No catch here: the caller's thread is the caller's (a gRPC reaction answers its own
  // errors); the core is given back even if the task throws.
  struct GiveBack {
    WorkerPool* pool;
    ~GiveBack() {
      if (pool != nullptr) pool->ReleaseCore(/*long_task=*/false, /*caller=*/true);
    }
  } give_back{this};
  // Short tasks queued before this one arrived go first.
  if (drain_ms > 0.0) RunQueuedHere(drain_ms, /*release_when_empty=*/false);
  {
    struct Timed {
      WorkerPool* pool = nullptr;
      std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
      ~Timed() {
        pool->Record(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
      }
    } timed{this};
    run_here_.fetch_add(1, std::memory_order_relaxed);
    task();
  }
  if (drain_ms > 0.0 && RunQueuedHere(drain_ms, /*release_when_empty=*/true)) give_back.pool = nullptr;
  return true;
}

bool WorkerPool::RunQueuedHere(double drain_ms, bool release_when_empty) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double, std::milli>(drain_ms);
  for (;;) {
    Task task;
    {
      std::lock_guard<std::mutex> lock(mu_);
      // Past the budget the rest is left to the workers, unless every one of them runs a
      // long task: with more cores than workers, short steps left queued would wait for one
      // of those to end while this core stood idle. Workers busy with short tasks take
      // over soon, and draining on past the budget then would hold this thread (and the
      // stream whose reaction it is) for as long as steps keep arriving.
      const bool workers_can_take_over = running_long_ < threads_started_;
      if (stopping_ || queue_.empty() || queue_.front().placement != Placement::kAnyCoreHolder ||
          (workers_can_take_over && std::chrono::steady_clock::now() >= until)) {
        if (release_when_empty && !stopping_ && queue_.empty()) {
          // Given back under the same lock that saw the queue empty: a task queued after
          // this point finds the core free and runs where it arrives; one queued before is
          // taken above. None waits for a worker that nobody wakes.
          busy_.fetch_sub(1, std::memory_order_relaxed);
          --running_;
          --running_here_;
          if (here_waiting_ > 0) core_free_.notify_one();
          return true;
        }
        return false;  // the caller gives the core back, waking a worker for what is queued
      }
      task = std::move(queue_.front());
      queue_.pop_front();
      queued_ms_ = queue_.empty() ? 0.0 : queued_ms_ - task.expected_ms;
    }
    const auto start = std::chrono::steady_clock::now();
    run_here_.fetch_add(1, std::memory_order_relaxed);
    RunQueued(task);
    Record(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  }
}

void WorkerPool::RunQueued(Task& task) {
  // Requests catch their own exceptions (RunCatchingExceptions) and answer with them;
  // this only keeps the thread alive should a task's bookkeeping throw anyway.
  try {
    task.run();
  } catch (const std::exception& e) {
    spdlog::error("worker pool: a task ended with an exception: {}", e.what());
  } catch (...) {
    spdlog::error("worker pool: a task ended with an unknown exception");
  }
  task.run = nullptr;  // its captures go before the core is given back
}

void WorkerPool::Run() {
  for (;;) {
    Task task;
    {
      std::unique_lock<std::mutex> lock(mu_);
      // A free core goes to a thread waiting in TryRunHere first (it takes the queue too).
      ready_.wait(lock, [this] {
        return (stopping_ && queue_.empty()) || (!queue_.empty() && running_ < cores_ && here_waiting_ == 0);
      });
      if (queue_.empty()) return;  // stopping and drained
      task = std::move(queue_.front());
      queue_.pop_front();
      queued_ms_ = queue_.empty() ? 0.0 : queued_ms_ - task.expected_ms;  // no drift when empty
      ++running_;
      if (task.placement == Placement::kWorker) ++running_long_;
    }
    const auto start = std::chrono::steady_clock::now();
    if (task.handed_to_idle_at.has_value()) {
      const double took_ms = std::chrono::duration<double, std::milli>(start - *task.handed_to_idle_at).count();
      const double before = handoff_ms_.load(std::memory_order_relaxed);
      handoff_ms_.store(before == 0.0 ? took_ms : 0.9 * before + 0.1 * took_ms, std::memory_order_relaxed);
    }
    busy_.fetch_add(1, std::memory_order_relaxed);
    const bool long_task = task.placement == Placement::kWorker;
    RunQueued(task);
    Record(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    ReleaseCore(long_task, /*caller=*/false);
  }
}

void WorkerPool::Record(double took_ms) {
  busy_seconds_.fetch_add(took_ms / 1000.0, std::memory_order_relaxed);
  std::lock_guard<std::mutex> lock(mu_);
  average_task_ms_ = average_task_ms_ == 0.0 ? took_ms : 0.9 * average_task_ms_ + 0.1 * took_ms;
}

void WorkerPool::ReleaseCore(bool long_task, bool caller) {
  busy_.fetch_sub(1, std::memory_order_relaxed);
  bool wake_here, wake_worker;
  {
    std::lock_guard<std::mutex> lock(mu_);
    --running_;
    if (long_task) --running_long_;
    if (caller) --running_here_;
    // A thread waiting in TryRunHere takes the core before the workers. Otherwise only
    // queued work needs a worker woken: waking an idle worker for nothing costs two
    // context switches per solve, on the core the next solve needs.
    wake_here = here_waiting_ > 0;
    wake_worker = !wake_here && !queue_.empty();
  }
  if (wake_here) core_free_.notify_one();
  if (wake_worker) ready_.notify_one();
}

}  // namespace nupmpc::server
