#include "loadtest/idle_sessions.h"

#include <chrono>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"

namespace nupmpc::loadtest {
namespace {

using Clock = std::chrono::steady_clock;

// The server trims freed heap at most once a second, after sessions went away.
constexpr auto kJanitorSettle = std::chrono::milliseconds(2500);

}  // namespace

absl::StatusOr<IdleSessionsReport> RunIdleSessions(const std::string& target, const v1::ProblemSpec& spec, int count,
                                                   bool wait_for_expiry) {
  Client client(target, std::chrono::seconds(30));
  IdleSessionsReport report;
  report.sessions = count;
  report.expired = wait_for_expiry;
  // Warm-up: one session through its whole life, then let the janitor settle.
  {
    absl::StatusOr<v1::CreateSessionResponse> first = client.CreateSession(spec);
    if (!first.ok()) return first.status();
    if (absl::Status s = client.CloseSession(first->session_id()); !s.ok()) return s;
    std::this_thread::sleep_for(kJanitorSettle);
  }
  absl::StatusOr<v1::GetServerInfoResponse> info = client.GetServerInfo();
  if (!info.ok()) return info.status();
  const std::uint32_t sessions_before = info->active_sessions();
  const double idle_timeout_s = info->limits().session_idle_timeout_s();
  report.compact_idle_s = info->limits().session_compact_idle_s();
  report.rss_before = info->resident_memory_bytes();
  v1::Step step;  // one solve from the spec's own initial state
  *step.mutable_state() = spec.initial_state().mean();

  std::vector<std::string> ids;
  ids.reserve(count);
  const Clock::time_point create_start = Clock::now();
  for (int i = 0; i < count; ++i) {
    absl::StatusOr<v1::CreateSessionResponse> created = client.CreateSession(spec);
    if (!created.ok()) {
      for (const std::string& id : ids) (void)client.CloseSession(id);
      return absl::Status(created.status().code(),
                          absl::StrCat("creating session ", i + 1, " of ", count, ": ", created.status().message()));
    }
    ids.push_back(created->session_id());
    if (absl::StatusOr<v1::SolveResult> solved = client.Solve(ids.back(), step); !solved.ok()) {
      for (const std::string& id : ids) (void)client.CloseSession(id);
      return absl::Status(solved.status().code(),
                          absl::StrCat("solving on session ", i + 1, ": ", solved.status().message()));
    }
  }
  report.create_s = std::chrono::duration<double>(Clock::now() - create_start).count();
  if (info = client.GetServerInfo(); !info.ok()) return info.status();
  report.rss_with_sessions = info->resident_memory_bytes();
  if (report.compact_idle_s > 0.0) {
    std::this_thread::sleep_for(std::chrono::duration<double>(report.compact_idle_s) + kJanitorSettle);
    if (info = client.GetServerInfo(); !info.ok()) return info.status();
  }
  report.rss_idle = info->resident_memory_bytes();

  const Clock::time_point release_start = Clock::now();
  if (wait_for_expiry) {
    const Clock::time_point give_up = release_start + std::chrono::duration_cast<Clock::duration>(
                                                          std::chrono::duration<double>(idle_timeout_s + 30.0));
    for (;;) {
      if (info = client.GetServerInfo(); !info.ok()) return info.status();
      if (info->active_sessions() <= sessions_before) break;
      if (Clock::now() > give_up) {
        return absl::DeadlineExceededError(
            absl::StrCat("sessions did not expire within the server's idle timeout (", idle_timeout_s, " s) + 30 s"));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  } else {
    for (const std::string& id : ids) {
      if (absl::Status s = client.CloseSession(id); !s.ok()) return s;
    }
  }
  report.release_s = std::chrono::duration<double>(Clock::now() - release_start).count();
  std::this_thread::sleep_for(kJanitorSettle);
  if (info = client.GetServerInfo(); !info.ok()) return info.status();
  report.rss_after = info->resident_memory_bytes();
  return report;
}

}  // namespace nupmpc::loadtest
