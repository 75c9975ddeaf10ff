#ifndef NUPMPC_SERVER_AUTH_TOKEN_FILE_H_
#define NUPMPC_SERVER_AUTH_TOKEN_FILE_H_

// The bearer tokens of --auth_tokens_file: one line per token, `TOKEN PRINCIPAL` or
// `TOKEN PRINCIPAL admin`, `#` starts a comment, blank lines are skipped.

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace nupmpc::server {

// Who a call comes from, as authentication established it.
struct Principal {
  std::string name;
  bool admin = false;
};

struct TokenGrant {
  std::string token;
  Principal principal;
};

// Errors name the file and line, never a token.
absl::StatusOr<std::vector<TokenGrant>> ParseTokenFile(absl::string_view text, absl::string_view file_name);

// Equality of two secrets in time that depends on their lengths only, not on where they
// first differ.
bool ConstantTimeEquals(absl::string_view a, absl::string_view b);

// The tokens file, re-read when it changes (ReloadIfChanged, called periodically). A file
// that no longer parses keeps the tokens read last. Thread-safe.
class TokenStore {
 public:
  // Reads `path`; an error when it is missing, unreadable or malformed.
  static absl::StatusOr<std::unique_ptr<TokenStore>> Open(std::string path);

  // The principal `token` belongs to. Every grant is compared, in constant time each, so
  // the time taken says nothing about which token came close.
  std::optional<Principal> Authenticate(absl::string_view token) const;
  // Whether some token of the file read last belongs to `principal`.
  bool HasPrincipal(absl::string_view principal) const;

  // Re-reads the file when its modification time, size or inode changed since the last
  // read. Returns whether new tokens took effect; an error when the changed file could not
  // be read or parsed (the previous tokens stay).
  absl::StatusOr<bool> ReloadIfChanged();
  const std::string& path() const { return path_; }
  std::size_t size() const;

 private:
  struct FileStamp {
    long long mtime_ns = -1;
    long long size = -1;
    unsigned long long inode = 0;
    bool operator==(const FileStamp&) const = default;
  };
  explicit TokenStore(std::string path) : path_(std::move(path)) {}
  absl::StatusOr<FileStamp> Stamp() const;
  absl::Status Read(const FileStamp& stamp);
  // The grants read last (a snapshot: a reload swaps in a new vector).
  std::shared_ptr<const std::vector<TokenGrant>> Grants() const;

  const std::string path_;
  mutable std::mutex mu_;
  std::shared_ptr<const std::vector<TokenGrant>> grants_;  // swapped whole under mu_
  FileStamp stamp_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_AUTH_TOKEN_FILE_H_
