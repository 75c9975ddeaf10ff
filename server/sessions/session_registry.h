#ifndef NUPMPC_SERVER_SESSIONS_SESSION_REGISTRY_H_
#define NUPMPC_SERVER_SESSIONS_SESSION_REGISTRY_H_

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/auth/caller.h"
#include "server/scheduling/session_strand.h"
#include "server/sessions/memory_budget.h"
#include "server/sessions/step_deadline.h"

namespace nupmpc::server {

using Clock = std::chrono::steady_clock;

// A session's share of the memory budget: what it keeps while it exists, and its solver
// scratch, given back while the session is compacted.
struct SessionMemory {
  MemoryBudget::Reservation resident;
  MemoryBudget::Reservation scratch;
  std::int64_t scratch_bytes = 0;      ///< what `scratch` holds when the scratch is allocated
  std::int64_t max_session_bytes = 0;  ///< the per-session limit when created (0: none)
};

// One client session: the core session (problem, workspace, warm start). Its strand
// serialises everything that uses the solver (solves, compaction, closing): the fields
// marked "strand" are used only by the task that holds it.
struct SessionEntry {
  std::string id;
  SessionOwner owner;  ///< fixed at creation: who may use it (server/auth/caller.h)
  bool owned_by_stream = false;
  SessionTiming timing;  ///< from the spec: time limit, period
  v1::Dimensions dims;   ///< fixed at creation: the caller's (MpcSession::dimensions)
  // The spec it was created from, kept by a server that writes snapshots (--state_dir):
  // a snapshot rebuilds the session from it (server/snapshots/). Null otherwise.
  std::shared_ptr<const v1::ProblemSpec> spec;
  bool restored = false;  ///< fixed at registration: restored from a snapshot

  std::unique_ptr<core::MpcSession> solver;  ///< strand; holds the session's problem
  bool compacted = false;                    ///< strand: solver scratch released while idle
  core::Solution solution;                   ///< strand; reused buffer
  bool closed = false;                       ///< strand: removed from the registry
  SessionMemory memory;                      ///< strand

  // One task at a time, none holding a worker while another one runs.
  const std::shared_ptr<SessionStrand> strand = std::make_shared<SessionStrand>();

  std::atomic<bool> attached{false};  ///< a Control stream uses it
  std::atomic<std::uint64_t> solves{0};
  // SolveFleet steps accepted for this session so far: a fleet step whose ticket (this
  // count when it was accepted) is below the count when it starts has been overtaken by a
  // newer one and is answered SUPERSEDED (server/rpc/fleet_call.h).
  std::atomic<std::uint64_t> fleet_steps_accepted{0};
  std::atomic<double> last_solve_ms{-1.0};  ///< the pool's wait estimate; -1: not solved yet
  // Its thread's CPU time (ThreadCpuTime), which a shared core does not inflate: where its
  // next Control step is solved (ControlStream::SolvesHere); -1: not solved yet.
  std::atomic<double> last_solve_cpu_ms{-1.0};
  // One message-passing pass of its last solve (wall time): the margin a step's deadline
  // leaves before its time limit (step_solver.cc).
  std::atomic<double> last_pass_ms{0.0};
  // The shortest pass of its solves so far (wall time; 0: none yet): a step left less time
  // than this is answered without a solve. The shortest, not the last: a pass slowed by a
  // shared core would otherwise turn away the session's next steps, and a step turned away
  // measures nothing that could correct it.
  std::atomic<double> shortest_pass_ms{0.0};
  std::atomic<Clock::rep> last_used{0};

  void Touch() { last_used.store(Clock::now().time_since_epoch().count(), std::memory_order_relaxed); }
  double idle_seconds() const;
  void Describe(v1::SessionInfo* out) const;  // fields readable without mu
  // Why Solve and SolveFleet may not step it (FAILED_PRECONDITION): a Control stream is
  // attached, or it belongs to one (a stream-owned session restored from a snapshot waits
  // for its stream's reconnect); OK otherwise.
  absl::Status UnaryStepsRefused() const;
  std::atomic<core::Algorithm> algorithm{core::Algorithm::kAuto};
};

// Session ids are 32 lower-case hex digits (128 random bits).
inline constexpr std::size_t kSessionIdLength = 32;
// INVALID_ARGUMENT for anything else (checked before any lookup).
absl::Status CheckSessionIdForm(absl::string_view id);
// A client-drawn id (CreateSessionRequest.session_id): the form the server's own ids have,
// 32 lower-case hex digits, so that the id a balancer hashed is the one every later call
// sends. INVALID_ARGUMENT naming the field otherwise.
absl::Status CheckRequestedSessionId(absl::string_view id);
// An id as error messages show it: at most its first 8 characters, escaped, and its length.
std::string QuoteSessionId(absl::string_view id);

// Sessions by unguessable id (128 random bits from the OS), with a maximum count and idle
// expiry. Thread-safe; lookups are short critical sections (never held during a solve).
class SessionRegistry {
 public:
  // `pool` runs the sessions' strands (closing or compacting a busy session queues on it).
  // `max_per_principal`: sessions one authenticated principal may hold (0: no own limit).
  SessionRegistry(int max_sessions, WorkerPool& pool, int max_per_principal = 0)
      : max_sessions_(max_sessions), max_per_principal_(max_per_principal), pool_(pool) {}

  // RESOURCE_EXHAUSTED when full, or when `owner`'s principal holds its quota. The session
  // gets `requested_id` (a form CheckSessionIdForm accepts: the client drew it, see
  // CreateSessionRequest.session_id) or, when empty, a new random id; ALREADY_EXISTS when
  // `requested_id` is taken.
  absl::StatusOr<std::shared_ptr<SessionEntry>> Add(std::unique_ptr<core::MpcSession> solver, SessionTiming timing,
                                                    bool owned_by_stream, SessionMemory memory = {},
                                                    absl::string_view requested_id = {}, SessionOwner owner = {},
                                                    std::shared_ptr<const v1::ProblemSpec> spec = nullptr,
                                                    bool restored = false);
  // The quota check of Add, for before the work of building a session.
  absl::Status CheckQuota(const SessionOwner& owner) const;
  // INVALID_ARGUMENT for malformed ids, NOT_FOUND for unknown (or closed, or expired) ones
  // and for those `caller` may not use (the same answer: their existence is not revealed).
  absl::StatusOr<std::shared_ptr<SessionEntry>> Find(const std::string& id, const Caller& caller = {}) const;
  // Removes the session at once; frees its solver and gives its memory back now, or right
  // after a solve in flight (solves waiting for it then find it closed), and then calls
  // `closed` (if given). Not called when the id is refused.
  absl::Status Close(const std::string& id, std::function<void()> closed = nullptr);
  std::vector<std::shared_ptr<SessionEntry>> List() const;
  // The sessions ListSessions shows `caller` (MayList).
  std::vector<std::shared_ptr<SessionEntry>> ListFor(const Caller& caller, bool list_all) const;
  // Closes sessions idle longer than `idle_seconds` that no stream is attached to.
  int ExpireIdle(double idle_seconds);
  // Releases the solver scratch (and its share of the memory budget) of sessions idle
  // longer than `idle_seconds`, skipping any that is solving right now; returns how many
  // it compacted.
  int CompactIdle(double idle_seconds);
  int size() const;
  int max_sessions() const { return max_sessions_; }
  // Since start: sessions created; closed (explicitly, with their stream, or by expiry);
  // of those, expired; and compactions (a session compacts again after each use).
  std::uint64_t created_total() const { return created_total_.load(std::memory_order_relaxed); }
  std::uint64_t closed_total() const { return closed_total_.load(std::memory_order_relaxed); }
  std::uint64_t expired_total() const { return expired_total_.load(std::memory_order_relaxed); }
  std::uint64_t compacted_total() const { return compacted_total_.load(std::memory_order_relaxed); }

 private:
  static std::string NewId();
  absl::Status CheckQuotaLocked(const SessionOwner& owner) const;
  const int max_sessions_;
  const int max_per_principal_;
  WorkerPool& pool_;
  mutable std::mutex mu_;
  std::unordered_map<std::string, std::shared_ptr<SessionEntry>> sessions_;
  std::unordered_map<std::string, int> per_principal_;  ///< sessions of each authenticated principal
  std::atomic<std::uint64_t> created_total_{0};
  std::atomic<std::uint64_t> closed_total_{0};
  std::atomic<std::uint64_t> expired_total_{0};
  std::atomic<std::uint64_t> compacted_total_{0};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_SESSION_REGISTRY_H_
