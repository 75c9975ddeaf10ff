#include "client/server_info_table.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/strip.h"

namespace nupmpc {
namespace {

using Rows = std::vector<std::pair<std::string, std::string>>;

std::string CpuBaseline(const v1::GetServerInfoResponse& info) {
  // Servers built before the field existed send nothing.
  if (info.cpu_baseline().empty()) return "(not reported)";
  if (info.cpu_features().empty()) return info.cpu_baseline();
  return absl::StrCat(info.cpu_baseline(), " (", info.cpu_features(), ")");
}

std::string Algorithms(const v1::GetServerInfoResponse& info) {
  std::vector<std::string> names;
  for (const int a : info.algorithms()) {
    names.push_back(
        absl::AsciiStrToLower(absl::StripPrefix(v1::Algorithm_Name(static_cast<v1::Algorithm>(a)), "ALGORITHM_")));
  }
  return names.empty() ? "(none)" : absl::StrJoin(names, ", ");
}

std::string Errors(const v1::GetServerInfoResponse& info) {
  // The proto map has no order; sort so that two listings compare line by line.
  std::vector<std::pair<std::string, uint64_t>> errors;
  for (const auto& [code, count] : info.errors_by_code()) errors.emplace_back(code, count);
  std::sort(errors.begin(), errors.end());
  std::vector<std::string> parts;
  for (const auto& [code, count] : errors) {
    if (count > 0) parts.push_back(absl::StrCat(code, " ", count));
  }
  return parts.empty() ? "none" : absl::StrJoin(parts, ", ");
}

// Only the buckets that counted something, "≤upper ms: count"; the last bucket (upper
// +Infinity) as ">previous upper ms".
std::string Latency(const v1::GetServerInfoResponse& info) {
  std::vector<std::string> parts;
  double previous = 0.0;
  for (const v1::LatencyBucket& b : info.solve_latency()) {
    if (b.count() > 0) {
      parts.push_back(std::isinf(b.upper_ms()) ? absl::StrFormat(">%g ms: %d", previous, b.count())
                                               : absl::StrFormat("≤%g ms: %d", b.upper_ms(), b.count()));
    }
    previous = b.upper_ms();
  }
  return parts.empty() ? "no solves yet" : absl::StrJoin(parts, ", ");
}

std::string Mib(std::uint64_t bytes) { return absl::StrFormat("%.1f MiB", static_cast<double>(bytes) / (1 << 20)); }

std::string Seconds(double s, const char* zero_means) { return s > 0 ? absl::StrFormat("%g s", s) : zero_means; }

}  // namespace

std::string ServerInfoTable(const v1::GetServerInfoResponse& info) {
  const v1::ServerLimits& l = info.limits();
  const Rows rows = {
      {"version", info.version()},
      {"api version", info.api_version()},
      {"CPU baseline", CpuBaseline(info)},
      {"algorithms", Algorithms(info)},
      {"active sessions", absl::StrCat(info.active_sessions())},
      {"solves", absl::StrCat(info.solves(), " (", info.solves_in_place(), " on the gRPC thread that received them)")},
      {"errors by code", Errors(info)},
      {"solve latency", Latency(info)},
      {"resident memory", Mib(info.resident_memory_bytes())},
      {"memory budget", absl::StrCat(Mib(info.memory_reserved_bytes()), " reserved of ", Mib(l.memory_budget_bytes()))},
      {"control streams", absl::StrCat(info.control_streams(), " open (max ", l.max_control_streams(), "), ",
                                       info.control_stream_read_pauses(), " read pauses")},
      {"draining", info.draining() ? "yes" : "no"},
      {"worker threads", absl::StrCat(l.worker_threads())},
      {"solver cores", absl::StrCat(l.solver_cores(), " (solves at once)")},
      {"queue capacity", absl::StrCat(l.queue_capacity())},
      {"max queue wait", l.max_queue_wait_ms() > 0 ? absl::StrFormat("%g ms", l.max_queue_wait_ms()) : "off"},
      {"solved where received", l.inline_solve_max_ms() > 0
                                    ? absl::StrFormat("steps of sessions solving in ≤%g ms", l.inline_solve_max_ms())
                                    : "never"},
      {"max sessions", absl::StrCat(l.max_sessions())},
      {"session idle timeout", Seconds(l.session_idle_timeout_s(), "never")},
      {"session compact idle", Seconds(l.session_compact_idle_s(), "never")},
      {"max horizon", absl::StrCat(l.max_horizon())},
      {"max states", absl::StrCat(l.max_states())},
      {"max inputs", absl::StrCat(l.max_inputs())},
      {"max outputs", absl::StrCat(l.max_outputs())},
      {"max iterations", absl::StrCat(l.max_iterations())},
      {"max GP points", absl::StrCat(l.max_gp_points())},
      {"max input levels", absl::StrCat(l.max_input_levels())},
      {"max keep-out regions", absl::StrCat(l.max_keep_out_regions())},
      {"max session memory", Mib(l.max_session_bytes())},
      {"max pass work", absl::StrFormat("%g GFLOP", l.max_pass_flops() * 1e-9)},
      {"max message", Mib(l.max_message_bytes())},
      {"stream answers unread", absl::StrCat("at most ", l.max_stream_answers())},
      {"calls per connection", absl::StrCat("at most ", l.max_streams_per_connection())},
      {"first message within", Seconds(l.first_message_timeout_s(), "no limit")},
      {"idle connections closed", Seconds(l.connection_idle_timeout_s(), "never")},
  };
  std::size_t width = 0;
  for (const auto& [key, value] : rows) width = std::max(width, key.size());
  std::string out;
  for (const auto& [key, value] : rows)
    absl::StrAppend(&out, key, std::string(width - key.size() + 2, ' '), value, "\n");
  return out;
}

}  // namespace nupmpc
