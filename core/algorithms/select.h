#ifndef NUPMPC_CORE_ALGORITHMS_SELECT_H_
#define NUPMPC_CORE_ALGORITHMS_SELECT_H_

#include <memory>

#include "absl/status/statusor.h"
#include "core/algorithms/outer_iteration.h"
#include "core/options.h"
#include "core/problem.h"

namespace nupmpc::core {

// The selection rule of nup-algorithms.md §4: constraints only on inputs → IBFFD;
// constraints on outputs (with or without inputs) → IFFBDD with augmented inputs if every
// input has a Gaussian part; otherwise IAKE. A forced algorithm is checked for
// applicability (FAILED_PRECONDITION naming the scalar that prevents it).
absl::StatusOr<Algorithm> SelectAlgorithm(const Problem& problem, Algorithm requested);

absl::StatusOr<std::unique_ptr<OuterIteration>> MakeOuterIteration(const Problem& problem,
                                                                   const SolverOptions& options);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_SELECT_H_
