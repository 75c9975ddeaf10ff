#ifndef NUPMPC_LOADTEST_BENCH_RANDOM_OUTPUT_BOX_H_
#define NUPMPC_LOADTEST_BENCH_RANDOM_OUTPUT_BOX_H_

#include <cstdint>

#include "core/nupmpc.h"

namespace nupmpc::bench {

// A random output-box problem of any horizon, drawn as the random_outbox benchmark
// instances were (benchmarks/README.md, nup-algorithms.md §13.4): A, B, C with
// entries iid N(0, 1/1000) (the instances' scaling at their horizon 1000, kept for every
// horizon so that the dynamics do not change with it), x[0] ~ N(0, I/M) as a decision
// variable, R = L·I, and at every step a two-sided box of half-width 0.1|y̌| around
// y̌ = y ⊙ (1 + U(-0.1, 0.1)), y the output of a simulation with inputs N(0, I/L).
// Deterministic for a seed with a given standard library (std::mt19937_64 and
// std::normal_distribution): a benchmark family, not test data.
core::Problem MakeRandomOutputBox(int M, int K, int L, int N, std::uint64_t seed);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_RANDOM_OUTPUT_BOX_H_
