#ifndef NUPMPC_TESTS_UTIL_RANDOM_PROBLEM_H_
#define NUPMPC_TESTS_UTIL_RANDOM_PROBLEM_H_

#include <random>

#include "core/problem.h"

namespace nupmpc::testing {

struct RandomProblemSpec {
  int M = 4, L = 2, K = 3, N = 20;
  bool time_varying = true;
  bool offsets = true;
  bool free_x0 = false;
  bool terminal = true;
  unsigned seed = 1;
};

// A random linear-Gaussian problem: every input has a Gaussian prior, outputs have Gaussian
// priors except a few free ones; A is scaled to spectral radius ≈ 0.9.
core::Problem RandomGaussianProblem(const RandomProblemSpec& spec);

// The same problem with hard boxes: every input in [-input_bound, input_bound] (0: none)
// and every output that has a Gaussian prior in [-output_bound, output_bound] (0: none),
// each keeping its Gaussian part. Inputs only: IBFFD's problem; outputs: IFFBDD's.
core::Problem WithBoxes(core::Problem problem, double input_bound, double output_bound);

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_RANDOM_PROBLEM_H_
