#include "server/snapshots/sealed_snapshot.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include <algorithm>
#include <chrono>
#include <utility>

#include "absl/strings/str_cat.h"
#include "server/snapshots/owner_only_file.h"

namespace nupmpc::server {
namespace {

// A key file is a secret of a few dozen bytes; anything much larger is a mistake.
constexpr std::size_t kMaxKeyFileBytes = 4096;

std::string Tag(absl::string_view payload, const SnapshotKey& key) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  if (key.keyed()) {
    HMAC(EVP_sha256(), key.secret().data(), static_cast<int>(key.secret().size()),
         reinterpret_cast<const unsigned char*>(payload.data()), payload.size(), digest, &length);
  } else {
    EVP_Digest(payload.data(), payload.size(), digest, &length, EVP_sha256(), nullptr);
  }
  return std::string(reinterpret_cast<const char*>(digest), length);
}

}  // namespace

absl::StatusOr<SnapshotKey> SnapshotKey::FromFile(const std::string& path) {
  absl::StatusOr<std::string> secret = ReadOwnerOnlyFile(path, kMaxKeyFileBytes, "--snapshot_key_file");
  if (!secret.ok()) return absl::InvalidArgumentError(secret.status().message());
  absl::StatusOr<SnapshotKey> key = FromBytes(*std::move(secret));
  if (!key.ok())
    return absl::InvalidArgumentError(absl::StrCat("--snapshot_key_file ", path, ": ", key.status().message()));
  return key;
}

absl::StatusOr<SnapshotKey> SnapshotKey::FromBytes(std::string secret) {
  if (secret.size() < kMinSnapshotKeyBytes) {
    return absl::InvalidArgumentError(absl::StrCat("a snapshot key needs at least ", kMinSnapshotKeyBytes,
                                                   " bytes (e.g. openssl rand -out FILE 32), got ", secret.size()));
  }
  SnapshotKey key;
  key.secret_ = std::move(secret);
  return key;
}

std::int64_t UnixMillisecondsNow() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string Seal(const snapshot::v1::SessionSnapshot& snapshot, const SnapshotKey& key) {
  snapshot::v1::SealedSnapshot sealed;
  sealed.set_seal_version(kSealVersion);
  sealed.set_payload(snapshot.SerializeAsString());
  sealed.set_tag(Tag(sealed.payload(), key));
  sealed.set_keyed(key.keyed());
  return sealed.SerializeAsString();
}

absl::StatusOr<snapshot::v1::SessionSnapshot> Unseal(absl::string_view bytes, const SnapshotKey& key,
                                                     std::size_t max_bytes) {
  if (const std::size_t limit = std::min(max_bytes, kMaxSnapshotBytes); bytes.size() > limit) {
    return absl::InvalidArgumentError(
        absl::StrCat("snapshot: ", bytes.size(), " bytes, more than the ", limit, " a session may take"));
  }
  if (bytes.empty()) return absl::InvalidArgumentError("snapshot: empty (a write that never finished?)");
  snapshot::v1::SealedSnapshot sealed;
  if (!sealed.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return absl::InvalidArgumentError("snapshot: not a sealed session snapshot");
  }
  if (sealed.seal_version() != kSealVersion) {
    return absl::InvalidArgumentError(
        absl::StrCat("snapshot: seal version ", sealed.seal_version(), ", this server reads ", kSealVersion));
  }
  if (sealed.keyed() != key.keyed()) {
    return absl::InvalidArgumentError(
        sealed.keyed() ? "snapshot: sealed with a key, and this server has none (--snapshot_key_file)"
                       : "snapshot: not sealed with a key, and this server requires one");
  }
  const std::string expected = Tag(sealed.payload(), key);
  if (sealed.tag().size() != expected.size() ||
      CRYPTO_memcmp(sealed.tag().data(), expected.data(), expected.size()) != 0) {
    return absl::InvalidArgumentError(key.keyed() ? "snapshot: integrity tag does not match (altered, or another key)"
                                                  : "snapshot: checksum does not match (corrupt)");
  }
  snapshot::v1::SessionSnapshot snapshot;
  if (!snapshot.ParseFromString(sealed.payload())) {
    return absl::InvalidArgumentError("snapshot: the sealed payload is not a session snapshot");
  }
  if (snapshot.format_version() != kSnapshotFormatVersion) {
    return absl::InvalidArgumentError(absl::StrCat("snapshot: format version ", snapshot.format_version(),
                                                   ", this server reads ", kSnapshotFormatVersion));
  }
  return snapshot;
}

}  // namespace nupmpc::server
