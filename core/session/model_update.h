#ifndef NUPMPC_CORE_SESSION_MODEL_UPDATE_H_
#define NUPMPC_CORE_SESSION_MODEL_UPDATE_H_

// A control period's changes to a session's model (the API's Step.model, ModelUpdate in
// proto/nupmpc/v1/nupmpc.proto): a nonlinear plant linearised along the previous plan
// (real-time iteration), a time-varying model moved with the horizon, or new affine terms
// (a disturbance estimate). The messages of a rejected update name the API's fields
// ("model.a[2].step = 40: ...").

#include <cstdint>
#include <optional>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "core/problem.h"

namespace nupmpc::core {

struct ModelChanges {
  template <typename Value>
  struct At {
    std::int64_t step = 0;  ///< wide enough for any index the API can send, so messages echo it
    Value value;
  };
  // First: every per-step term moves one step earlier, the last step repeated.
  bool shift = false;
  // Then the affine terms of every step: M (K) values for all steps, or N·M ((N+1)·K)
  // step-major.
  std::optional<Eigen::VectorXd> state_offsets, output_offsets;
  // Then single steps: A, B, c at steps < N; C, d at steps ≤ N.
  std::vector<At<Eigen::MatrixXd>> A, B, C;
  std::vector<At<Eigen::VectorXd>> state_offset, output_offset;

  bool empty() const {
    return !shift && !state_offsets.has_value() && !output_offsets.has_value() && A.empty() && B.empty() && C.empty() &&
           state_offset.empty() && output_offset.empty();
  }
};

// The model terms of a Problem, as a session keeps a candidate of them (the same vectors,
// so that copying into it reuses its storage and swapping it in is free).
struct ModelTerms {
  std::vector<Eigen::MatrixXd> A, B, C;
  std::vector<Eigen::VectorXd> state_offset, output_offset;
};
void CopyModelTerms(const Problem& from, ModelTerms* to);
void SwapModelTerms(Problem* problem, ModelTerms* terms);

// INVALID_ARGUMENT naming the field unless every step index is in range and given once
// per term, and every matrix and vector has the session's size and finite values.
absl::Status CheckModelChanges(const Problem& problem, const ModelChanges& changes);

// Whether the changes make a time-invariant A, B or C per-step (the factor graph then
// needs to be built again). After CheckModelChanges.
bool ModelChangesStorage(const Problem& problem, const ModelChanges& changes);

// Writes checked changes into `terms`, a copy of the model terms of a problem with
// `problem`'s dimensions.
void WriteModelChanges(const ModelChanges& changes, const Problem& problem, ModelTerms* terms);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_MODEL_UPDATE_H_
