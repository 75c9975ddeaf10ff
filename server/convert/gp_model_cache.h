#ifndef NUPMPC_SERVER_CONVERT_GP_MODEL_CACHE_H_
#define NUPMPC_SERVER_CONVERT_GP_MODEL_CACHE_H_

#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>

#include "absl/functional/function_ref.h"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"

namespace nupmpc::server {

// Factorised GP models shared by the sessions built from the same training data and kernel.
// A model costs O(P²) memory (its Cholesky factor, P² doubles) and O(P³) time to build, and
// many sessions use the same one (a controller per unit of one plant type, sessions
// re-created after a reconnect). A model lives as long as a session holds it. A GpModel is
// immutable after creation and safe to share between threads. A build that fails or is
// stopped (the caller's deadline or cancellation) is not cached, and no request waits for
// another's build: each runs its own, so a stopped build holds up nobody.
class GpModelCache {
 public:
  // The model for `key` (canonical bytes of the data, lags and kernel), built by `make` when
  // no live session holds one. Two concurrent builds of one key may both run; the first to
  // finish is kept and returned to both.
  absl::StatusOr<std::shared_ptr<const gp::GpModel>> GetOrCreate(const std::string& key,
                                                                 absl::FunctionRef<absl::StatusOr<gp::GpModel>()> make);
  // Models some session holds now.
  int live_models() const;

 private:
  mutable std::mutex mu_;
  std::unordered_map<std::string, std::weak_ptr<const gp::GpModel>> models_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_GP_MODEL_CACHE_H_
