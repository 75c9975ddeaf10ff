#include "server/principal_streams.h"

#include "absl/strings/str_cat.h"

namespace nupmpc::server {

absl::Status PrincipalStreams::Acquire(const std::string& principal) {
  if (principal.empty()) return absl::OkStatus();
  std::lock_guard<std::mutex> lock(mu_);
  int& open = open_[principal];
  if (max_per_principal_ > 0 && open >= max_per_principal_) {
    if (open == 0) open_.erase(principal);
    return absl::ResourceExhaustedError(absl::StrCat("max_streams_per_principal: principal \"", principal,
                                                     "\" has its quota of ", max_per_principal_,
                                                     " Control streams open; close one first"));
  }
  ++open;
  return absl::OkStatus();
}

void PrincipalStreams::Release(const std::string& principal) {
  if (principal.empty()) return;
  std::lock_guard<std::mutex> lock(mu_);
  const auto it = open_.find(principal);
  if (it != open_.end() && --it->second == 0) open_.erase(it);
}

}  // namespace nupmpc::server
