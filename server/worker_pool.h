#ifndef NUPMPC_SERVER_WORKER_POOL_H_
#define NUPMPC_SERVER_WORKER_POOL_H_

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace nupmpc::server {

// A fixed set of solver threads with a bounded queue. Solves are CPU-bound: the pool is
// sized to the cores the server may use (two by design), and a full queue is reported to
// the caller (RESOURCE_EXHAUSTED) instead of growing latency without bound.
class WorkerPool {
 public:
  WorkerPool(int threads, int queue_capacity);
  ~WorkerPool();  // Shutdown()
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Queues a task; false when the queue is full or the pool is shut down.
  bool TrySubmit(std::function<void()> task);
  // Stops accepting, runs what is queued, joins the threads. Idempotent.
  void Shutdown();

  int threads() const { return static_cast<int>(threads_.size()); }
  int queue_capacity() const { return capacity_; }
  int queued() const;

 private:
  void Run();

  const int capacity_;
  mutable std::mutex mu_;
  std::condition_variable ready_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_WORKER_POOL_H_
