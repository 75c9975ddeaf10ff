#ifndef NUPMPC_SERVER_SESSION_REGISTRY_H_
#define NUPMPC_SERVER_SESSION_REGISTRY_H_

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/session/mpc_session.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/input_transform.h"
#include "server/memory_budget.h"
#include "server/session_strand.h"

namespace nupmpc::server {

using Clock = std::chrono::steady_clock;

// A session's share of the memory budget: what it keeps while it exists, and its solver
// scratch, given back while the session is compacted.
struct SessionMemory {
  MemoryBudget::Reservation resident;
  MemoryBudget::Reservation scratch;
  std::int64_t scratch_bytes = 0;  ///< what `scratch` holds when the scratch is allocated
};

// One client session: the core session (problem, workspace, warm start). `mu` serialises
// solves: one solve at a time per session.
struct SessionEntry {
  std::string id;
  bool owned_by_stream = false;
  double default_time_limit_ms = 0.0;  ///< from the spec's options
  v1::Dimensions dims;                 ///< fixed at creation (the spec's, before any transform)

  std::mutex mu;
  std::unique_ptr<core::MpcSession> solver;  ///< guarded by mu; holds the session's problem
  Eigen::VectorXd x0;                     ///< guarded by mu; the measured state being applied
  InputTransform transform;               ///< guarded by mu; multi-level / Δu mapping
  bool compacted = false;                 ///< guarded by mu: solver scratch released while idle
  core::Solution solution;                ///< guarded by mu; reused buffer
  bool closed = false;                    ///< guarded by mu: removed from the registry
  SessionMemory memory;                   ///< guarded by mu

  // Solves of this session go through its strand: one at a time, none holding a worker
  // while another one runs.
  const std::shared_ptr<SessionStrand> strand = std::make_shared<SessionStrand>();

  std::atomic<bool> attached{false};  ///< a Control stream uses it
  std::atomic<std::uint64_t> solves{0};
  std::atomic<double> last_solve_ms{-1.0};  ///< the pool's wait estimate; -1: not solved yet
  std::atomic<Clock::rep> last_used{0};

  void Touch() { last_used.store(Clock::now().time_since_epoch().count(), std::memory_order_relaxed); }
  double idle_seconds() const;
  void Describe(v1::SessionInfo* out) const;  // fields readable without mu
  std::atomic<core::Algorithm> algorithm{core::Algorithm::kAuto};
};

// Session ids are 32 lower-case hex digits (128 random bits).
inline constexpr std::size_t kSessionIdLength = 32;
// INVALID_ARGUMENT for anything else (checked before any lookup).
absl::Status CheckSessionIdForm(absl::string_view id);
// An id as error messages show it: at most its first 8 characters, escaped, and its length.
std::string QuoteSessionId(absl::string_view id);

// Sessions by unguessable id (128 random bits from the OS), with a maximum count and idle
// expiry. Thread-safe; lookups are short critical sections (never held during a solve).
class SessionRegistry {
 public:
  explicit SessionRegistry(int max_sessions) : max_sessions_(max_sessions) {}

  // RESOURCE_EXHAUSTED when full.
  absl::StatusOr<std::shared_ptr<SessionEntry>> Add(std::unique_ptr<core::MpcSession> solver,
                                                    double default_time_limit_ms, bool owned_by_stream,
                                                    InputTransform transform = {}, SessionMemory memory = {});
  // INVALID_ARGUMENT for malformed ids, NOT_FOUND for unknown (or closed, or expired) ones.
  absl::StatusOr<std::shared_ptr<SessionEntry>> Find(const std::string& id) const;
  // Frees the session's solver and gives its memory back at once (after a solve in flight).
  absl::Status Close(const std::string& id);
  std::vector<std::shared_ptr<SessionEntry>> List() const;
  // Closes sessions idle longer than `idle_seconds` that no stream is attached to.
  int ExpireIdle(double idle_seconds);
  // Releases the solver scratch (and its share of the memory budget) of sessions idle
  // longer than `idle_seconds`, skipping any that is solving right now; returns how many
  // it compacted.
  int CompactIdle(double idle_seconds);
  int size() const;
  int max_sessions() const { return max_sessions_; }
  // Sessions closed since start (explicitly, with their stream, or by expiry).
  std::uint64_t closed_total() const { return closed_total_.load(std::memory_order_relaxed); }

 private:
  static std::string NewId();
  const int max_sessions_;
  mutable std::mutex mu_;
  std::unordered_map<std::string, std::shared_ptr<SessionEntry>> sessions_;
  std::atomic<std::uint64_t> closed_total_{0};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSION_REGISTRY_H_
