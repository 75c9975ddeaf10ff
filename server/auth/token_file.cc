#include "server/auth/token_file.h"

#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace nupmpc::server {

absl::StatusOr<std::vector<TokenGrant>> ParseTokenFile(absl::string_view text, absl::string_view file_name) {
  std::vector<TokenGrant> grants;
  int line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    if (const std::size_t comment = line.find('#'); comment != absl::string_view::npos) line = line.substr(0, comment);
    const std::vector<absl::string_view> fields = absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (fields.empty()) continue;
    const auto where = [&] { return absl::StrCat(file_name, ":", line_number, ": "); };
    if (fields.size() < 2 || fields.size() > 3) {
      return absl::InvalidArgumentError(
          absl::StrCat(where(), "expected TOKEN PRINCIPAL [admin], found ", fields.size(), " fields"));
    }
    if (fields.size() == 3 && fields[2] != "admin") {
      return absl::InvalidArgumentError(absl::StrCat(where(), "the third field may only be \"admin\""));
    }
    // Short tokens can be guessed; the check asks for 128 bits' worth of hex or base64.
    if (fields[0].size() < 16) {
      return absl::InvalidArgumentError(absl::StrCat(where(), "the token is shorter than 16 characters"));
    }
    for (const TokenGrant& earlier : grants) {
      if (earlier.token == fields[0]) {
        return absl::InvalidArgumentError(absl::StrCat(where(), "the token repeats an earlier line's"));
      }
    }
    grants.push_back({std::string(fields[0]), {std::string(fields[1]), fields.size() == 3}});
  }
  return grants;
}

bool ConstantTimeEquals(absl::string_view a, absl::string_view b) {
  // Every byte of the longer one is visited; the length difference is folded in at the end.
  const std::size_t n = std::max(a.size(), b.size());
  unsigned char difference = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    difference |= static_cast<unsigned char>(x ^ y);
  }
  // Keeps the compiler from turning the loop into an early exit.
  volatile unsigned char result = difference;
  return result == 0;
}

absl::StatusOr<std::unique_ptr<TokenStore>> TokenStore::Open(std::string path) {
  std::unique_ptr<TokenStore> store(new TokenStore(std::move(path)));
  absl::StatusOr<FileStamp> stamp = store->Stamp();
  if (!stamp.ok()) return stamp.status();
  if (absl::Status read = store->Read(*stamp); !read.ok()) return read;
  return store;
}

absl::StatusOr<TokenStore::FileStamp> TokenStore::Stamp() const {
  struct stat st {};
  if (stat(path_.c_str(), &st) != 0) {
    return absl::NotFoundError(absl::StrCat("--auth_tokens_file ", path_, ": ", std::strerror(errno)));
  }
  return FileStamp{static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec,
                   static_cast<long long>(st.st_size), static_cast<unsigned long long>(st.st_ino)};
}

absl::Status TokenStore::Read(const FileStamp& stamp) {
  std::ifstream in(path_);
  if (!in) return absl::NotFoundError(absl::StrCat("--auth_tokens_file ", path_, ": cannot be read"));
  std::stringstream text;
  text << in.rdbuf();
  absl::StatusOr<std::vector<TokenGrant>> grants = ParseTokenFile(text.str(), path_);
  std::lock_guard<std::mutex> lock(mu_);
  stamp_ = stamp;  // a bad file is reported once, not at every check
  if (!grants.ok()) return grants.status();
  grants_ = std::make_shared<const std::vector<TokenGrant>>(*std::move(grants));
  return absl::OkStatus();
}

absl::StatusOr<bool> TokenStore::ReloadIfChanged() {
  absl::StatusOr<FileStamp> stamp = Stamp();
  if (!stamp.ok()) {
    // A missing file is reported once, not at every check; the tokens read last stay.
    const FileStamp missing{.mtime_ns = -2};
    std::lock_guard<std::mutex> lock(mu_);
    if (stamp_ == missing) return false;
    stamp_ = missing;
    return stamp.status();
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (*stamp == stamp_) return false;
  }
  if (absl::Status read = Read(*stamp); !read.ok()) return read;
  return true;
}

std::shared_ptr<const std::vector<TokenGrant>> TokenStore::Grants() const {
  std::lock_guard<std::mutex> lock(mu_);
  return grants_;
}

std::optional<Principal> TokenStore::Authenticate(absl::string_view token) const {
  const std::shared_ptr<const std::vector<TokenGrant>> grants = Grants();
  std::optional<Principal> found;
  for (const TokenGrant& grant : *grants) {
    if (ConstantTimeEquals(grant.token, token) && !found.has_value()) found = grant.principal;
  }
  return found;
}

bool TokenStore::HasPrincipal(absl::string_view principal) const {
  const std::shared_ptr<const std::vector<TokenGrant>> grants = Grants();
  for (const TokenGrant& grant : *grants) {
    if (grant.principal.name == principal) return true;
  }
  return false;
}

std::size_t TokenStore::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return grants_->size();
}

}  // namespace nupmpc::server
