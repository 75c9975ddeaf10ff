#ifndef NUPMPC_LOADTEST_IDLE_SESSIONS_H_
#define NUPMPC_LOADTEST_IDLE_SESSIONS_H_

// The memory side of nupmpc-loadtest: create many sessions and solve once on each (so
// each holds a warm start), read the server's RSS (GetServerInfo) right away and once the
// server has compacted them as idle, let them go (CloseSession, or wait for the server's
// idle expiry), and read it again once the janitor has handed the memory back. "Before"
// is read after one session was created and closed, so gRPC's and the allocator's
// one-time set-up is not counted as session memory.

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::loadtest {

struct IdleSessionsReport {
  int sessions = 0;
  std::uint64_t rss_before = 0;         ///< bytes, before the first session
  std::uint64_t rss_with_sessions = 0;  ///< bytes, all sessions open, just used
  std::uint64_t rss_idle = 0;           ///< bytes, all open, compacted as idle by the server
  double compact_idle_s = 0.0;          ///< the server's setting (0: never compacts)
  std::uint64_t rss_after = 0;          ///< bytes, after they were closed or expired
  double create_s = 0.0;
  double release_s = 0.0;  ///< until the server reported them gone
  bool expired = false;    ///< released by idle expiry rather than CloseSession
};

absl::StatusOr<IdleSessionsReport> RunIdleSessions(const std::string& target, const v1::ProblemSpec& spec, int count,
                                                   bool wait_for_expiry);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_IDLE_SESSIONS_H_
