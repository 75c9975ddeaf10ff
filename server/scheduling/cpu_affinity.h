#ifndef NUPMPC_SERVER_SCHEDULING_CPU_AFFINITY_H_
#define NUPMPC_SERVER_SCHEDULING_CPU_AFFINITY_H_

// CPU affinity as Linux CPU lists ("0", "0-3", "0,2-3"): what GetServerInfo reports of the
// server process, and how nupmpc-loadtest pins itself and its peers for a fair comparison.

#include <sched.h>

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace nupmpc::server {

// `list` ("0", "1-3", "0,2-3") as a set; INVALID_ARGUMENT naming the part that is not a CPU
// number or range, or a CPU beyond CPU_SETSIZE.
absl::StatusOr<cpu_set_t> ParseCpuList(absl::string_view list);
// The set as a CPU list, ranges joined ("0-3,6").
std::string CpuList(const cpu_set_t& set);
// The CPUs the calling thread may run on (the process's, unless a thread changed its own).
std::string CallingThreadCpuList();
// Restricts the calling thread (and the threads and processes it starts afterwards) to `set`.
absl::Status PinCallingThread(const cpu_set_t& set);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SCHEDULING_CPU_AFFINITY_H_
