#ifndef NUPMPC_FUZZ_SEED_PROBLEM_H_
#define NUPMPC_FUZZ_SEED_PROBLEM_H_

// The fuzz targets' fixed problem and steps: two masses on springs (M = 4, L = 1, K = 4,
// N = 10) with input and output boxes and a terminal cost: small enough for thousands of
// solves a second, with every kind of prior a step may update.

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::fuzz {

v1::ProblemSpec SeedSpec();
// The step for state number `k` of a fixed sequence (k = 0 is the initial state).
v1::Step SeedStep(int k);

}  // namespace nupmpc::fuzz

#endif  // NUPMPC_FUZZ_SEED_PROBLEM_H_
