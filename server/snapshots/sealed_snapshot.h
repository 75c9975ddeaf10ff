#ifndef NUPMPC_SERVER_SNAPSHOTS_SEALED_SNAPSHOT_H_
#define NUPMPC_SERVER_SNAPSHOTS_SEALED_SNAPSHOT_H_

// A session snapshot's bytes as they leave the process (a file in --state_dir, shared by
// replicas or kept across a restart) and come back: sealed with an integrity tag that is
// checked before a byte of the snapshot itself is parsed.
//  * With the replicas' shared key (--snapshot_key_file): HMAC-SHA256. A snapshot someone
//    without the key wrote or altered is refused, so nobody can restore a session under a
//    principal it was not created by.
//  * Without a key: SHA-256, which catches corruption (a torn write, a flipped bit) but not
//    forgery: for a state directory only this server's user can write.
// A server with a key refuses unkeyed snapshots, and one without a key refuses keyed ones
// (it cannot check them). Versions are refused, never guessed: kSealVersion for the seal,
// kSnapshotFormatVersion for the snapshot inside.

#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "nupmpc/snapshot/v1/session_snapshot.pb.h"

namespace nupmpc::server {

inline constexpr std::uint32_t kSealVersion = 1;
inline constexpr std::uint32_t kSnapshotFormatVersion = 1;

// The key the replicas share, or none.
class SnapshotKey {
 public:
  SnapshotKey() = default;  // none
  // The file's whole content is the key; at least 32 bytes, a regular file readable by its
  // owner only (like the TLS key). INVALID_ARGUMENT naming --snapshot_key_file otherwise.
  static absl::StatusOr<SnapshotKey> FromFile(const std::string& path);
  static absl::StatusOr<SnapshotKey> FromBytes(std::string secret);
  bool keyed() const { return !secret_.empty(); }
  const std::string& secret() const { return secret_; }

 private:
  std::string secret_;
};

inline constexpr std::size_t kMinSnapshotKeyBytes = 32;
// The largest snapshot read at all, whatever the limits: protobuf parses at most 2 GiB, and
// a server reading one snapshot must not hold more than a fraction of its memory for it.
inline constexpr std::size_t kMaxSnapshotBytes = std::size_t{1} << 30;

std::string Seal(const snapshot::v1::SessionSnapshot& snapshot, const SnapshotKey& key);

// The wall clock snapshots are stamped with (SessionSnapshot.written_unix_ms) and aged by.
std::int64_t UnixMillisecondsNow();

// INVALID_ARGUMENT saying what is wrong (larger than `max_bytes` or kMaxSnapshotBytes, not a sealed snapshot,
// another seal or format version, a key mismatch, a tag that does not match).
absl::StatusOr<snapshot::v1::SessionSnapshot> Unseal(absl::string_view bytes, const SnapshotKey& key,
                                                     std::size_t max_bytes);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SNAPSHOTS_SEALED_SNAPSHOT_H_
