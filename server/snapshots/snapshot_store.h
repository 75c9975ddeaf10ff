#ifndef NUPMPC_SERVER_SNAPSHOTS_SNAPSHOT_STORE_H_
#define NUPMPC_SERVER_SNAPSHOTS_SNAPSHOT_STORE_H_

// --state_dir: one file per session, `<id>.snapshot`, sealed (sealed_snapshot.h) and
// owner-only. A draining server writes its sessions here; a server asked for a session it
// does not hold claims the file (Claim), restores it and removes the file. The directory
// may be this server's own (a restart) or shared by the replicas behind one balancer (a
// drain hands sessions to whichever replica the client reconnects to), with the shared key.
//
// A snapshot is kept for `reattach_window_s` after it was written: an older one is not
// restored (its client has long re-created its session) and is removed when found.
// Files that fail their checks are skipped with a log line naming them, and left in place:
// in a shared directory a file this server cannot read may be another replica's (another
// key or format version during a rolling update), and some errors pass (no descriptor
// free). Such a file is checked again when its session's client asks for it.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "nupmpc/snapshot/v1/session_snapshot.pb.h"
#include "server/auth/caller.h"
#include "server/snapshots/sealed_snapshot.h"

namespace nupmpc::server {

struct SnapshotStoreOptions {
  std::string dir;
  SnapshotKey key;
  std::size_t max_snapshot_bytes = 0;  ///< a file larger than this is refused
  double reattach_window_s = 0.0;
};

class SnapshotStore {
 public:
  // Creates the directory if missing (0700) and checks every file in it (size, seal,
  // version), with a log line for each that fails.
  static absl::StatusOr<std::unique_ptr<SnapshotStore>> Open(SnapshotStoreOptions options);

  absl::Status Write(const snapshot::v1::SessionSnapshot& snapshot);

  // The snapshot of session `id` for `caller`: NOT_FOUND when there is none (or it is too
  // old, refused, claimed by another replica first, or not the caller's: the same answer,
  // and another caller's file stays). A returned snapshot's file is gone: its session is
  // the caller's to restore (or lose: the client then re-creates it cold).
  // A stream-owned session's snapshot is for its stream's reconnect only: a unary call
  // (`by_control_stream` false) gets NOT_FOUND for it, and the file stays.
  absl::StatusOr<snapshot::v1::SessionSnapshot> Claim(const std::string& id, const Caller& caller,
                                                      bool by_control_stream = true);

  // How many files Open found valid, and since then: written, claimed, refused.
  std::uint64_t found_at_start() const { return found_at_start_; }
  std::uint64_t written() const;
  std::uint64_t claimed() const;
  std::uint64_t refused() const;
  const std::string& dir() const { return options_.dir; }

 private:
  explicit SnapshotStore(SnapshotStoreOptions options) : options_(std::move(options)) {}
  std::string PathOf(const std::string& id) const;
  // Reads and checks one file; on failure logs why.
  absl::StatusOr<snapshot::v1::SessionSnapshot> ReadChecked(const std::string& path, const std::string& id);
  bool TooOld(const snapshot::v1::SessionSnapshot& snapshot) const;

  const SnapshotStoreOptions options_;
  std::uint64_t found_at_start_ = 0;
  mutable std::mutex mu_;  ///< the counters
  std::uint64_t written_ = 0, claimed_ = 0, refused_ = 0;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SNAPSHOTS_SNAPSHOT_STORE_H_
