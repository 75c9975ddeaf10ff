#include "core/solution.h"

#include "absl/strings/str_cat.h"

namespace nupmpc::core {

std::optional<SolveStatus> LimitReached(const SolveLimits& limits, double elapsed_seconds) {
  if (limits.cancel != nullptr && limits.cancel->load(std::memory_order_relaxed)) return SolveStatus::kCancelled;
  if (limits.time_limit_seconds > 0.0 && elapsed_seconds >= limits.time_limit_seconds) return SolveStatus::kTimeLimit;
  return std::nullopt;
}

const char* SolveStatusName(SolveStatus status) {
  switch (status) {
    case SolveStatus::kConverged:
      return "converged";
    case SolveStatus::kIterationLimit:
      return "iteration_limit";
    case SolveStatus::kTimeLimit:
      return "time_limit";
    case SolveStatus::kNumericalError:
      return "numerical_error";
    case SolveStatus::kCancelled:
      return "cancelled";
    case SolveStatus::kInfeasible:
      return "infeasible";
  }
  return "unknown";
}

std::string SolveSummary::Describe() const {
  return absl::StrCat(AlgorithmName(algorithm), ": ", SolveStatusName(status), " after ", iterations, " iterations",
                      polished ? " (polished)" : "", elastic ? " (elastic)" : "", warm_started ? ", warm" : "",
                      ", J = ", objective, ", max violation = ", max_violation,
                      linearisations > 0 ? absl::StrCat(", ", linearisations,
                                                        " linearisations, nonlinear violation = ", nonlinear_violation)
                                         : "");
}

}  // namespace nupmpc::core
