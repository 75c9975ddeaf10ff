#include "server/sessions/session_registry.h"

#include <algorithm>
#include <random>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/public/status_macros.h"
#include "server/convert/result_conversion.h"
#include "server/observability/log_context.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {

double SessionEntry::idle_seconds() const {
  const Clock::duration since = Clock::now().time_since_epoch() - Clock::duration(last_used.load());
  return std::chrono::duration<double>(since).count();
}

void SessionEntry::Describe(v1::SessionInfo* out) const {
  out->set_session_id(id);
  *out->mutable_dimensions() = dims;
  out->set_algorithm(AlgorithmToProto(algorithm.load()));
  out->set_solves(solves.load(std::memory_order_relaxed));
  out->set_idle_s(idle_seconds());
  out->set_owned_by_stream(owned_by_stream);
  out->set_attached(attached.load(std::memory_order_relaxed));
}

absl::Status SessionEntry::UnaryStepsRefused() const {
  if (attached.load()) {
    return absl::FailedPreconditionError("session_id: a Control stream is attached to this session; send steps there");
  }
  if (owned_by_stream) {
    return absl::FailedPreconditionError(
        "session_id: the session belongs to a Control stream; re-attach a Control stream to step it");
  }
  return absl::OkStatus();
}

std::string SessionRegistry::NewId() {
  // std::random_device reads the kernel's CSPRNG (getrandom) on Linux.
  static thread_local std::random_device device;
  std::string id;
  for (int i = 0; i < 4; ++i) absl::StrAppend(&id, absl::StrFormat("%08x", device()));
  return id;
}

absl::StatusOr<std::shared_ptr<SessionEntry>> SessionRegistry::Add(
    std::unique_ptr<core::MpcSession> solver, SessionTiming timing, bool owned_by_stream, SessionMemory memory,
    absl::string_view requested_id, SessionOwner owner, std::shared_ptr<const v1::ProblemSpec> spec, bool restored) {
  auto entry = std::make_shared<SessionEntry>();
  entry->owner = std::move(owner);
  entry->spec = std::move(spec);
  entry->restored = restored;
  entry->owned_by_stream = owned_by_stream;
  entry->timing = timing;
  entry->algorithm = solver->algorithm();
  const core::Dimensions dims = solver->dimensions();
  entry->dims.set_num_states(dims.num_states);
  entry->dims.set_num_inputs(dims.num_inputs);
  entry->dims.set_num_outputs(dims.num_outputs);
  entry->dims.set_horizon(dims.horizon);
  entry->solver = std::move(solver);
  entry->memory = std::move(memory);
  entry->Touch();
  std::lock_guard<std::mutex> lock(mu_);
  if (static_cast<int>(sessions_.size()) >= max_sessions_) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the server holds its maximum of ", max_sessions_, " sessions; close one or retry later"));
  }
  NUPMPC_RETURN_IF_ERROR(CheckQuotaLocked(entry->owner));
  if (!requested_id.empty()) {
    entry->id = std::string(requested_id);
    if (sessions_.count(entry->id) > 0) {
      return absl::AlreadyExistsError(absl::StrCat("session_id ", QuoteSessionId(requested_id),
                                                   ": a session with this id exists; draw another one"));
    }
  } else {
    do {
      entry->id = NewId();
    } while (sessions_.count(entry->id) > 0);
  }
  sessions_.emplace(entry->id, entry);
  if (!entry->owner.principal.empty()) ++per_principal_[entry->owner.principal];
  created_total_.fetch_add(1, std::memory_order_relaxed);
  return entry;
}

std::string QuoteSessionId(absl::string_view id) {
  constexpr std::size_t kShown = 8;
  if (id.size() <= kShown) return absl::StrCat("\"", absl::CHexEscape(id), "\"");
  return absl::StrCat("\"", absl::CHexEscape(id.substr(0, kShown)), "...\" (", id.size(), " characters)");
}

absl::Status CheckRequestedSessionId(absl::string_view id) {
  const bool lower_hex =
      std::all_of(id.begin(), id.end(), [](char c) { return absl::ascii_isdigit(c) || (c >= 'a' && c <= 'f'); });
  if (id.size() == kSessionIdLength && lower_hex) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat("CreateSessionRequest.session_id ", QuoteSessionId(id), ": must be ",
                                                 kSessionIdLength,
                                                 " lower-case hex digits drawn at random, or empty for an id the "
                                                 "server draws"));
}

absl::Status CheckSessionIdForm(absl::string_view id) {
  const bool hex = std::all_of(id.begin(), id.end(), [](char c) { return absl::ascii_isxdigit(c); });
  if (id.size() == kSessionIdLength && hex) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat("session_id ", QuoteSessionId(id), ": must be ", kSessionIdLength,
                                                 " hex digits, as CreateSession returns it"));
}

absl::Status SessionRegistry::CheckQuota(const SessionOwner& owner) const {
  std::lock_guard<std::mutex> lock(mu_);
  return CheckQuotaLocked(owner);
}

absl::Status SessionRegistry::CheckQuotaLocked(const SessionOwner& owner) const {
  if (max_per_principal_ <= 0 || owner.principal.empty()) return absl::OkStatus();
  const auto it = per_principal_.find(owner.principal);
  if (it == per_principal_.end() || it->second < max_per_principal_) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat("max_sessions_per_principal: principal \"", owner.principal,
                                                   "\" holds its quota of ", max_per_principal_,
                                                   " sessions; close one first"));
}

absl::StatusOr<std::shared_ptr<SessionEntry>> SessionRegistry::Find(const std::string& id, const Caller& caller) const {
  NUPMPC_RETURN_IF_ERROR(CheckSessionIdForm(id));
  std::lock_guard<std::mutex> lock(mu_);
  const auto it = sessions_.find(id);
  if (it == sessions_.end() || !MayUse(caller, it->second->owner)) {
    return absl::NotFoundError(absl::StrCat("session_id ", QuoteSessionId(id), ": no such session"));
  }
  return it->second;
}

absl::Status SessionRegistry::Close(const std::string& id, std::function<void()> closed) {
  // NOLINTNEXTLINE(performance-no-automatic-move): NUPMPC_RETURN_IF_ERROR's const local (core/util/status_macros.h)
  NUPMPC_RETURN_IF_ERROR(CheckSessionIdForm(id));
  std::shared_ptr<SessionEntry> entry;
  {
    std::lock_guard<std::mutex> lock(mu_);
    const auto it = sessions_.find(id);
    if (it == sessions_.end())
      return absl::NotFoundError(absl::StrCat("session_id ", QuoteSessionId(id), ": no such session"));
    entry = std::move(it->second);
    sessions_.erase(it);
    if (!entry->owner.principal.empty()) {
      const auto count = per_principal_.find(entry->owner.principal);
      if (--count->second == 0) per_principal_.erase(count);
    }
  }
  closed_total_.fetch_add(1, std::memory_order_relaxed);
  SessionStrand::RunExclusive(entry->strand, pool_, [entry, closed = std::move(closed)] {
    entry->closed = true;
    entry->solver.reset();
    entry->memory = SessionMemory{};
    if (closed) closed();
  });
  return absl::OkStatus();
}

int SessionRegistry::CompactIdle(double idle_seconds) {
  int compacted = 0;
  for (const std::shared_ptr<SessionEntry>& entry : List()) {
    if (entry->idle_seconds() <= idle_seconds) continue;
    // A busy session is not idle: skip it.
    SessionStrand::RunNowIfIdle(entry->strand, pool_, [&] {
      if (entry->closed || entry->compacted) return;
      entry->solver->ReleaseWorkspace();
      entry->memory.scratch.Release();
      entry->compacted = true;
      ++compacted;
    });
  }
  compacted_total_.fetch_add(static_cast<std::uint64_t>(compacted), std::memory_order_relaxed);
  return compacted;
}

std::vector<std::shared_ptr<SessionEntry>> SessionRegistry::List() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<std::shared_ptr<SessionEntry>> out;
  out.reserve(sessions_.size());
  for (const auto& [id, entry] : sessions_) out.push_back(entry);
  return out;
}

std::vector<std::shared_ptr<SessionEntry>> SessionRegistry::ListFor(const Caller& caller, bool list_all) const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<std::shared_ptr<SessionEntry>> out;
  for (const auto& [id, entry] : sessions_) {
    if (MayList(caller, entry->owner, list_all)) out.push_back(entry);
  }
  return out;
}

int SessionRegistry::ExpireIdle(double idle_seconds) {
  std::vector<std::pair<std::string, std::string>> expired;  // id, owner's principal
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [id, entry] : sessions_) {
      if (!entry->attached.load() && entry->idle_seconds() > idle_seconds)
        expired.emplace_back(id, entry->owner.principal);
    }
  }
  int closed = 0;
  for (const auto& [id, principal] : expired) {
    if (!Close(id).ok()) continue;  // closed meanwhile by its client
    ++closed;
    const LogContext log_context(id, principal);
    spdlog::info("session {} closed: idle longer than {} s", id, idle_seconds);
  }
  expired_total_.fetch_add(static_cast<std::uint64_t>(closed), std::memory_order_relaxed);
  return closed;
}

int SessionRegistry::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int>(sessions_.size());
}

}  // namespace nupmpc::server
