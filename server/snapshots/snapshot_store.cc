#include "server/snapshots/snapshot_store.h"

#include <dirent.h>
#include <unistd.h>

#include <cstdio>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "server/sessions/session_registry.h"
#include "server/snapshots/owner_only_file.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {
namespace {

constexpr absl::string_view kSuffix = ".snapshot";

// The session ids of the directory's snapshot files (other names are not ours: left alone).
std::vector<std::string> SnapshotIds(const std::string& dir) {
  std::vector<std::string> ids;
  DIR* d = opendir(dir.c_str());
  if (d == nullptr) return ids;
  while (const dirent* e = readdir(d)) {
    absl::string_view name = e->d_name;
    if (!absl::ConsumeSuffix(&name, kSuffix)) continue;
    if (CheckSessionIdForm(name).ok()) ids.emplace_back(name);
  }
  closedir(d);
  return ids;
}

}  // namespace

absl::StatusOr<std::unique_ptr<SnapshotStore>> SnapshotStore::Open(SnapshotStoreOptions options) {
  if (const absl::Status dir = PrepareOwnerOnlyDirectory(options.dir, "--state_dir"); !dir.ok()) {
    return absl::InvalidArgumentError(dir.message());
  }
  std::unique_ptr<SnapshotStore> store(new SnapshotStore(std::move(options)));
  for (const std::string& id : SnapshotIds(store->options_.dir)) {
    if (store->ReadChecked(store->PathOf(id), id).ok()) ++store->found_at_start_;
  }
  spdlog::info("--state_dir {}: {} session snapshots to restore when their clients come back ({} refused)",
               store->options_.dir, store->found_at_start_, store->refused());
  return store;
}

std::string SnapshotStore::PathOf(const std::string& id) const { return absl::StrCat(options_.dir, "/", id, kSuffix); }

bool SnapshotStore::TooOld(const snapshot::v1::SessionSnapshot& snapshot) const {
  return static_cast<double>(UnixMillisecondsNow() - snapshot.written_unix_ms()) > options_.reattach_window_s * 1e3;
}

absl::StatusOr<snapshot::v1::SessionSnapshot> SnapshotStore::ReadChecked(const std::string& path,
                                                                         const std::string& id) {
  absl::StatusOr<std::string> bytes = ReadOwnerOnlyFile(path, options_.max_snapshot_bytes, "snapshot");
  if (!bytes.ok() && absl::IsNotFound(bytes.status())) return bytes.status();
  absl::StatusOr<snapshot::v1::SessionSnapshot> snapshot =
      bytes.ok() ? Unseal(*bytes, options_.key, options_.max_snapshot_bytes)
                 : absl::StatusOr<snapshot::v1::SessionSnapshot>(bytes.status());
  if (snapshot.ok() && snapshot->session_id() != id) {
    snapshot = absl::InvalidArgumentError(absl::StrCat(
        "snapshot: holds session ", QuoteSessionId(snapshot->session_id()), ", not the one its file is named after"));
  }
  if (!snapshot.ok()) {
    // Left where it is: in a shared directory it may be another replica's to read (another
    // key or format version during a rolling update), and an error may be passing (no
    // descriptor free). Never read as a session, it is only named in the log.
    spdlog::error("{}: skipped, not restored: {}", path, std::string(snapshot.status().message()));
    std::lock_guard<std::mutex> lock(mu_);
    ++refused_;
    return snapshot.status();
  }
  if (TooOld(*snapshot)) {
    unlink(path.c_str());
    spdlog::info("{}: older than the re-attach window ({} s), removed", path, options_.reattach_window_s);
    return absl::NotFoundError("snapshot: older than the re-attach window");
  }
  return snapshot;
}

absl::Status SnapshotStore::Write(const snapshot::v1::SessionSnapshot& snapshot) {
  absl::Status written = WriteOwnerOnlyFileAtomically(PathOf(snapshot.session_id()), Seal(snapshot, options_.key));
  if (written.ok()) {
    std::lock_guard<std::mutex> lock(mu_);
    ++written_;
  }
  return written;
}

absl::StatusOr<snapshot::v1::SessionSnapshot> SnapshotStore::Claim(const std::string& id, const Caller& caller,
                                                                   bool by_control_stream) {
  const absl::Status not_found =
      absl::NotFoundError(absl::StrCat("session_id ", QuoteSessionId(id), ": no such session"));
  if (!CheckSessionIdForm(id).ok()) return not_found;
  const std::string path = PathOf(id);
  absl::StatusOr<snapshot::v1::SessionSnapshot> snapshot = ReadChecked(path, id);
  if (!snapshot.ok()) return not_found;
  if (!MayUse(caller, SessionOwner{snapshot->owner_principal(), snapshot->owner_connection()})) return not_found;
  if (snapshot->owned_by_stream() && !by_control_stream) return not_found;
  // The rename is atomic: of replicas claiming the same file at once, one gets it.
  const std::string claimed = absl::StrCat(path, ".claimed.", getpid());
  if (std::rename(path.c_str(), claimed.c_str()) != 0) return not_found;
  unlink(claimed.c_str());
  std::lock_guard<std::mutex> lock(mu_);
  ++claimed_;
  return snapshot;
}

std::uint64_t SnapshotStore::written() const {
  std::lock_guard<std::mutex> lock(mu_);
  return written_;
}
std::uint64_t SnapshotStore::claimed() const {
  std::lock_guard<std::mutex> lock(mu_);
  return claimed_;
}
std::uint64_t SnapshotStore::refused() const {
  std::lock_guard<std::mutex> lock(mu_);
  return refused_;
}

}  // namespace nupmpc::server
