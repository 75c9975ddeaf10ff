#include "core/session/model_update.h"

#include <set>
#include <string>
#include <type_traits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

template <typename Value>
absl::Status CheckEntries(const std::vector<ModelChanges::At<Value>>& entries, const char* field, int steps,
                          const char* steps_name, int rows, int cols) {
  std::set<std::int64_t> seen;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const auto& e = entries[i];
    const std::string path = absl::StrCat("model.", field, "[", i, "]");
    if (e.step < 0 || e.step >= steps) {
      return Invalid(absl::StrCat(path, ".step = ", e.step, ": must be < ", steps_name, " = ", steps));
    }
    if (!seen.insert(e.step).second) {
      return Invalid(absl::StrCat(path, ".step = ", e.step, ": that step is given twice"));
    }
    if constexpr (std::is_same_v<Value, Eigen::MatrixXd>) {
      if (e.value.rows() != rows || e.value.cols() != cols) {
        return Invalid(
            absl::StrCat(path, ".matrix: expected ", rows, "x", cols, ", got ", e.value.rows(), "x", e.value.cols()));
      }
      if (!e.value.allFinite()) return Invalid(absl::StrCat(path, ".matrix: contains a non-finite number"));
    } else {
      if (e.value.size() != rows) {
        return Invalid(absl::StrCat(path, ".values: expected ", rows, " values, got ", e.value.size()));
      }
      if (!e.value.allFinite()) return Invalid(absl::StrCat(path, ".values: contains a non-finite number"));
    }
  }
  return absl::OkStatus();
}

absl::Status CheckAllSteps(const std::optional<Eigen::VectorXd>& values, const char* field, int width, int steps) {
  if (!values.has_value()) return absl::OkStatus();
  const auto size = values->size();
  if (size != width && size != static_cast<Eigen::Index>(width) * steps) {
    return Invalid(absl::StrCat("model.", field, ": expected ", width, " values (every step) or ", width * steps, " (",
                                steps, " steps), got ", size));
  }
  if (!values->allFinite()) return Invalid(absl::StrCat("model.", field, ": contains a non-finite number"));
  return absl::OkStatus();
}

// Step n+1 becomes step n, the last step stays (swaps: no allocation).
template <typename T>
void ShiftSteps(std::vector<T>* terms) {
  if (terms->size() < 2) return;
  for (std::size_t n = 0; n + 1 < terms->size(); ++n) std::swap((*terms)[n], (*terms)[n + 1]);
  terms->back() = (*terms)[terms->size() - 2];
}

void WriteAllSteps(const Eigen::VectorXd& values, int width, int steps, std::vector<Eigen::VectorXd>* terms) {
  if (values.size() == width) {
    if (static_cast<int>(terms->size()) == steps) {
      for (Eigen::VectorXd& t : *terms) t = values;  // kept per-step: no allocation
    } else {
      terms->assign(1, values);
    }
    return;
  }
  terms->resize(steps);
  for (int n = 0; n < steps; ++n) (*terms)[n] = values.segment(static_cast<Eigen::Index>(n) * width, width);
}

// Single steps of a term of `rows`×`cols` values per step; a time-invariant (or absent,
// zero) term first becomes `steps` copies.
template <typename Value>
void WriteEntries(const std::vector<ModelChanges::At<Value>>& entries, int steps, int rows, int cols,
                  std::vector<Value>* terms) {
  if (entries.empty()) return;
  if (static_cast<int>(terms->size()) != steps) {
    const Value value = terms->empty() ? Value(Value::Zero(rows, cols)) : terms->front();
    terms->assign(steps, value);
  }
  for (const auto& e : entries) (*terms)[e.step] = e.value;
}

}  // namespace

void CopyModelTerms(const Problem& from, ModelTerms* to) {
  to->A = from.A;
  to->B = from.B;
  to->C = from.C;
  to->state_offset = from.state_offset;
  to->output_offset = from.output_offset;
}

void SwapModelTerms(Problem* problem, ModelTerms* terms) {
  problem->A.swap(terms->A);
  problem->B.swap(terms->B);
  problem->C.swap(terms->C);
  problem->state_offset.swap(terms->state_offset);
  problem->output_offset.swap(terms->output_offset);
}

absl::Status CheckModelChanges(const Problem& p, const ModelChanges& m) {
  const int M = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  NUPMPC_RETURN_IF_ERROR(CheckAllSteps(m.state_offsets, "state_offsets", M, N));
  NUPMPC_RETURN_IF_ERROR(CheckAllSteps(m.output_offsets, "output_offsets", K, N + 1));
  NUPMPC_RETURN_IF_ERROR(CheckEntries(m.A, "a", N, "horizon", M, M));
  NUPMPC_RETURN_IF_ERROR(CheckEntries(m.B, "b", N, "horizon", M, L));
  NUPMPC_RETURN_IF_ERROR(CheckEntries(m.C, "c", N + 1, "horizon + 1", K, M));
  NUPMPC_RETURN_IF_ERROR(CheckEntries(m.state_offset, "state_offset", N, "horizon", M, 1));
  NUPMPC_RETURN_IF_ERROR(CheckEntries(m.output_offset, "output_offset", N + 1, "horizon + 1", K, 1));
  return absl::OkStatus();
}

bool ModelChangesStorage(const Problem& p, const ModelChanges& m) {
  return (!m.A.empty() && p.A.size() == 1) || (!m.B.empty() && p.B.size() == 1) || (!m.C.empty() && p.C.size() == 1);
}

void WriteModelChanges(const ModelChanges& m, const Problem& p, ModelTerms* terms) {
  const int M = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  if (m.shift) {
    ShiftSteps(&terms->A);
    ShiftSteps(&terms->B);
    ShiftSteps(&terms->C);
    ShiftSteps(&terms->state_offset);
    ShiftSteps(&terms->output_offset);
  }
  if (m.state_offsets.has_value()) WriteAllSteps(*m.state_offsets, M, N, &terms->state_offset);
  if (m.output_offsets.has_value()) WriteAllSteps(*m.output_offsets, K, N + 1, &terms->output_offset);
  WriteEntries(m.A, N, M, M, &terms->A);
  WriteEntries(m.B, N, M, L, &terms->B);
  WriteEntries(m.C, N + 1, K, M, &terms->C);
  WriteEntries(m.state_offset, N, M, 1, &terms->state_offset);
  WriteEntries(m.output_offset, N + 1, K, 1, &terms->output_offset);
}

}  // namespace nupmpc::core
