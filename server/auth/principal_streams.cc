#include "server/auth/principal_streams.h"

#include <utility>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {

absl::Status PrincipalStreams::Acquire(const std::string& principal, const void* key, std::function<void()> revoke) {
  if (principal.empty()) return absl::OkStatus();
  std::lock_guard<std::mutex> lock(mu_);
  auto& streams = open_[principal];
  if (max_per_principal_ > 0 && static_cast<int>(streams.size()) >= max_per_principal_) {
    if (streams.empty()) open_.erase(principal);
    return absl::ResourceExhaustedError(absl::StrCat("max_streams_per_principal: principal \"", principal,
                                                     "\" has its quota of ", max_per_principal_,
                                                     " Control streams open; close one first"));
  }
  streams[key] = std::move(revoke);
  return absl::OkStatus();
}

void PrincipalStreams::Release(const std::string& principal, const void* key) {
  if (principal.empty()) return;
  std::lock_guard<std::mutex> lock(mu_);
  const auto it = open_.find(principal);
  if (it == open_.end()) return;
  it->second.erase(key);
  if (it->second.empty()) open_.erase(it);
}

std::vector<std::function<void()>> PrincipalStreams::Revoked(
    const std::function<bool(const std::string&)>& has_access) {
  std::vector<std::function<void()>> revoked;
  std::lock_guard<std::mutex> lock(mu_);
  for (const auto& [principal, streams] : open_) {
    if (has_access(principal)) continue;
    for (const auto& [key, revoke] : streams) {
      if (revoke) revoked.push_back(revoke);
    }
  }
  return revoked;
}

}  // namespace nupmpc::server
