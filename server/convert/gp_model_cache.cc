#include "server/convert/gp_model_cache.h"

namespace nupmpc::server {

absl::StatusOr<std::shared_ptr<const gp::GpModel>> GpModelCache::GetOrCreate(
    const std::string& key, absl::FunctionRef<absl::StatusOr<gp::GpModel>()> make) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    const auto it = models_.find(key);
    if (it != models_.end()) {
      if (std::shared_ptr<const gp::GpModel> live = it->second.lock()) return live;
    }
  }
  // Built outside the lock: O(P³), and other keys must not wait for it.
  absl::StatusOr<gp::GpModel> built = make();
  if (!built.ok()) return built.status();
  auto model = std::make_shared<const gp::GpModel>(*std::move(built));
  std::lock_guard<std::mutex> lock(mu_);
  for (auto it = models_.begin(); it != models_.end();) {  // forget models no session holds
    it = it->second.expired() ? models_.erase(it) : std::next(it);
  }
  auto [it, inserted] = models_.emplace(key, model);
  if (!inserted) {
    if (std::shared_ptr<const gp::GpModel> first = it->second.lock()) return first;
    it->second = model;
  }
  return model;
}

int GpModelCache::live_models() const {
  std::lock_guard<std::mutex> lock(mu_);
  int live = 0;
  for (const auto& [key, model] : models_) live += model.expired() ? 0 : 1;
  return live;
}

}  // namespace nupmpc::server
