#ifndef NUPMPC_CORE_MODEL_MULTILEVEL_INPUTS_H_
#define NUPMPC_CORE_MODEL_MULTILEVEL_INPUTS_H_

// M-level inputs as sums of equally weighted binaries (nup-algorithms.md §5.4, [KL]
// §III-D): an input restricted to {β0, β0 + β, …, β0 + Jβ} is written u = β0 + β Σ_j z_j
// with J binaries z_j ∈ {0, 1}. The model does the sum: input column b becomes J columns
// β b, and β0 b joins the state offset. Equal weights work; powers of two do not.
//
// The binaries of one input are interchangeable, so each starts from a slightly different
// NUP variance (symmetry breaking, [KL] eq. 80): ScalarPrior::initial_variance.

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/problem.h"

namespace nupmpc::core {

// The levels of one input: β0 + β·{0, 1, …, count-1}; count = 0 leaves the input as it is.
struct InputLevels {
  int count = 0;  ///< number of levels M ≥ 2 (J = M - 1 binaries); 0: not multi-level
  double lowest = 0.0;
  double spacing = 1.0;  ///< β > 0
};

// The expanded problem: inputs are ordered input by input (an untouched input keeps one
// column, a multi-level one has count-1 binary columns). A multi-level input must have no
// prior of its own (a cost on u would couple its binaries): INVALID_ARGUMENT naming the
// field; put costs on the plant's response through outputs instead. `em` picks the
// binaries' estimation variant.
absl::StatusOr<Problem> ExpandMultiLevelInputs(const Problem& problem, const std::vector<InputLevels>& levels,
                                               bool em = true);

// The original inputs (N × L) of a plan of the expanded problem (N × L').
Eigen::MatrixXd InputsFromLevels(const Eigen::MatrixXd& expanded_inputs, const std::vector<InputLevels>& levels);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_MODEL_MULTILEVEL_INPUTS_H_
