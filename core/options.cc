#include "core/options.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace nupmpc::core {

const char* AlgorithmName(Algorithm algorithm) {
  switch (algorithm) {
    case Algorithm::kAuto:
      return "auto";
    case Algorithm::kIake:
      return "iake";
    case Algorithm::kIbffd:
      return "ibffd";
    case Algorithm::kIffbdd:
      return "iffbdd";
  }
  return "unknown";
}

absl::StatusOr<Algorithm> ParseAlgorithm(const std::string& name) {
  for (Algorithm a : {Algorithm::kAuto, Algorithm::kIake, Algorithm::kIbffd, Algorithm::kIffbdd}) {
    if (name == AlgorithmName(a)) return a;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("algorithm = \"", name, "\"; must be one of auto, iake, ibffd, iffbdd"));
}

namespace {
absl::Status Positive(const char* field, double value) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    return absl::InvalidArgumentError(absl::StrCat("SolverOptions.", field, " = ", value, "; must be finite and > 0"));
  }
  return absl::OkStatus();
}
absl::Status AtLeast(const char* field, int value, int min) {
  if (value < min) {
    return absl::InvalidArgumentError(absl::StrCat("SolverOptions.", field, " = ", value, "; must be >= ", min));
  }
  return absl::OkStatus();
}
absl::Status Fraction(const char* field, double value) {
  if (!(value >= 0.0 && value < 1.0)) {
    return absl::InvalidArgumentError(absl::StrCat("SolverOptions.", field, " = ", value, "; must be in [0, 1)"));
  }
  return absl::OkStatus();
}
}  // namespace

absl::Status Validate(const SolverOptions& o) {
  for (const auto& [field, value] :
       {std::pair{"objective_tolerance", o.objective_tolerance},
        std::pair{"violation_tolerance", o.violation_tolerance}, std::pair{"iake_hard_slope", o.iake_hard_slope},
        std::pair{"ibffd_initial_halfspace_slope", o.ibffd_initial_halfspace_slope},
        std::pair{"ibffd_initial_box_slope", o.ibffd_initial_box_slope}}) {
    if (absl::Status s = Positive(field, value); !s.ok()) return s;
  }
  if (!(o.iake_variance_floor >= 0.0) || !std::isfinite(o.iake_variance_floor)) {
    return absl::InvalidArgumentError(
        absl::StrCat("SolverOptions.iake_variance_floor = ", o.iake_variance_floor, "; must be finite and >= 0"));
  }
  if (absl::Status s = AtLeast("max_iterations", o.max_iterations, 1); !s.ok()) return s;
  if (!(o.elastic_slope >= 0.0) || !std::isfinite(o.elastic_slope)) {
    return absl::InvalidArgumentError(
        absl::StrCat("SolverOptions.elastic_slope = ", o.elastic_slope, "; must be finite and >= 0 (0: off)"));
  }
  if (absl::Status s = AtLeast("elastic_after_iterations", o.elastic_after_iterations, 1); !s.ok()) return s;
  if (absl::Status s = AtLeast("polish_after_stable_iterations", o.polish_after_stable_iterations, 0); !s.ok())
    return s;
  if (absl::Status s = AtLeast("polish_rounds", o.polish_rounds, 0); !s.ok()) return s;
  if (absl::Status s = AtLeast("discrete_fixing_passes", o.discrete_fixing_passes, 0); !s.ok()) return s;
  if (absl::Status s = AtLeast("discrete_fixing_blocks", o.discrete_fixing_blocks, 1); !s.ok()) return s;
  if (absl::Status s = AtLeast("discrete_search_sweeps", o.discrete_search_sweeps, 0); !s.ok()) return s;
  if (absl::Status s = AtLeast("discrete_pair_reach", o.discrete_pair_reach, 0); !s.ok()) return s;
  if (absl::Status s = AtLeast("polish_max_rounds", o.polish_max_rounds, o.polish_rounds); !s.ok()) return s;
  if (absl::Status s = Fraction("polish_settled_fraction", o.polish_settled_fraction); !s.ok()) return s;
  if (absl::Status s = Fraction("input_polish_settled_fraction", o.input_polish_settled_fraction); !s.ok()) return s;
  return absl::OkStatus();
}

absl::Status Validate(const SolveLimits& l) {
  if (l.max_iterations < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("SolveLimits.max_iterations = ", l.max_iterations, "; must be >= 0"));
  }
  if (!(l.time_limit_seconds >= 0.0) || std::isnan(l.time_limit_seconds)) {
    return absl::InvalidArgumentError(
        absl::StrCat("SolveLimits.time_limit_seconds = ", l.time_limit_seconds, "; must be >= 0"));
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::core
