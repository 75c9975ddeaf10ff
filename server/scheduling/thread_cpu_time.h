#ifndef NUPMPC_SERVER_SCHEDULING_THREAD_CPU_TIME_H_
#define NUPMPC_SERVER_SCHEDULING_THREAD_CPU_TIME_H_

#include <chrono>
#include <ctime>

namespace nupmpc::server {

// The CPU time the calling thread has used so far. Unlike wall time it does not grow while
// the thread waits for its core (another thread's time slice), so it says how long work
// holds a thread, whatever else shares the machine.
inline std::chrono::nanoseconds ThreadCpuTime() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return std::chrono::seconds(now.tv_sec) + std::chrono::nanoseconds(now.tv_nsec);
}

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SCHEDULING_THREAD_CPU_TIME_H_
