#ifndef NUPMPC_CORE_MODEL_INPUT_DIFFERENCES_H_
#define NUPMPC_CORE_MODEL_INPUT_DIFFERENCES_H_

// Priors on input differences Δu[n] = u[n] - u[n-1] (rate limits, move suppression,
// sparse level switches) by model augmentation, so callers state "constrain Δu" and never
// build the augmented model themselves ([KL] §V-B, versions 2 and 5).
//
// The augmented problem carries the last applied input in its state and decides the
// differences:
//
//   x'[n] = [x[n]; u[n-1]],   u'[n] = Δu[n],
//   A' = [[A, B], [0, I]],  B' = [[B], [I]],  c' = [c; 0],  x'[0] = [x[0]; u[-1]]
//   y'[n] = [C x[n] + d; u[n-1]]   (K original outputs, then L outputs carrying the inputs)
//
// A prior on u[n] becomes a prior on output K + l at step n + 1; a prior on Δu[n] is the
// augmented input prior. The terminal cost is extended by zeros. The solver then sees an
// ordinary problem: every algorithm and prior kind applies as usual.

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/problem.h"

namespace nupmpc::core {

// `delta_priors`: N·L priors on Δu (index n·L + l); `previous_input`: u[-1], the input
// applied before this horizon (size L). The problem's own input priors move to outputs.
// INVALID_ARGUMENT naming the field when a size or value is wrong.
absl::StatusOr<Problem> AugmentWithInputDifferences(const Problem& problem,
                                                    const std::vector<ScalarPrior>& delta_priors,
                                                    const Eigen::VectorXd& previous_input);

// The inputs u (N × L, row n = u[n]) of a plan of the augmented problem, whose inputs are
// the differences (N × L): u[n] = u[-1] + Δu[0] + … + Δu[n].
Eigen::MatrixXd InputsFromDifferences(const Eigen::MatrixXd& differences, const Eigen::VectorXd& previous_input);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_MODEL_INPUT_DIFFERENCES_H_
