#include "server/scheduling/cpu_affinity.h"

#include <cerrno>
#include <cstring>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace nupmpc::server {
namespace {

absl::StatusOr<int> CpuNumber(absl::string_view text, absl::string_view part) {
  int cpu = -1;
  if (!absl::SimpleAtoi(text, &cpu) || cpu < 0 || cpu >= CPU_SETSIZE) {
    return absl::InvalidArgumentError(
        absl::StrCat("CPU list: \"", part, "\" is not a CPU number (0 to ", CPU_SETSIZE - 1, ") or range A-B"));
  }
  return cpu;
}

}  // namespace

absl::StatusOr<cpu_set_t> ParseCpuList(absl::string_view list) {
  cpu_set_t set;
  CPU_ZERO(&set);
  for (absl::string_view part : absl::StrSplit(list, ',')) {
    const std::vector<absl::string_view> ends = absl::StrSplit(part, absl::MaxSplits('-', 1));
    absl::StatusOr<int> first = CpuNumber(ends[0], part);
    if (!first.ok()) return first.status();
    absl::StatusOr<int> last = ends.size() == 2 ? CpuNumber(ends[1], part) : first;
    if (!last.ok()) return last.status();
    if (*last < *first)
      return absl::InvalidArgumentError(absl::StrCat("CPU list: range \"", part, "\" runs backwards"));
    for (int cpu = *first; cpu <= *last; ++cpu) CPU_SET(cpu, &set);
  }
  return set;
}

std::string CpuList(const cpu_set_t& set) {
  std::string out;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (!CPU_ISSET(cpu, &set)) continue;
    int last = cpu;
    while (last + 1 < CPU_SETSIZE && CPU_ISSET(last + 1, &set)) ++last;
    absl::StrAppend(&out, out.empty() ? "" : ",", cpu);
    if (last > cpu) absl::StrAppend(&out, "-", last);
    cpu = last;
  }
  return out;
}

std::string CallingThreadCpuList() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) != 0) return "";
  return CpuList(set);
}

absl::Status PinCallingThread(const cpu_set_t& set) {
  if (sched_setaffinity(0, sizeof(set), &set) != 0) {
    const int error = errno;
    return absl::InvalidArgumentError(absl::StrCat("cannot run on CPUs ", CpuList(set), ": ", std::strerror(error)));
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::server
