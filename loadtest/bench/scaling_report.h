#ifndef NUPMPC_LOADTEST_BENCH_SCALING_REPORT_H_
#define NUPMPC_LOADTEST_BENCH_SCALING_REPORT_H_

#include <cstddef>
#include <memory>
#include <vector>

#include "core/public/session.h"
#include "loadtest/bench/bench_report.h"
#include "loadtest/bench/instance_result.h"

namespace nupmpc::bench {

// nupmpc-bench --scaling: cost per horizon step across horizons (a solve must stay linear
// in N), each sweep's instances solved again interleaved.

// An instance of a sweep, kept to be solved again.
struct ScalingEntry {
  std::unique_ptr<core::Session> session;
  std::size_t result;  ///< index into the results it updates
};

// Solves every entry cold once per round, the order reversed every round, and sets each
// entry's solve_ms (median) and GFLOP/s: the machine's speed drifts between seconds, and
// instances measured one after the other would compare different moments.
void MeasureInterleaved(std::vector<ScalingEntry>& entries, int rounds, std::vector<InstanceResult>& results);

// One sweep's table (sorted by N): µs per horizon step and ns per iteration and step, each
// relative to N = 300 (in cache there), and the flop rate next to the GEMM rate at n = gemm_n.
void PrintScaling(std::vector<const InstanceResult*> rows, int gemm_n, double gemm, bool json);

// The sweep on generated random output-box problems (random_output_box.h; M = 40,
// K = L = 20) at N = 300, 3000 and 30000: IFFBDD's own passes over a long horizon (masses
// spends most of its passes in the input polish). Returns the number of failed instances.
int RunGeneratedScaling(const BenchOptions& options, double gemm40);

// The rate of the per-stage kernels at M = 20 and 40 next to GEMM at that n: generated
// random output boxes (M = 20, K = L = 10; M = 40, K = L = 20) at N = 300, solved with
// IFFBDD's own passes (interior_point = false), each a full filter pass (the M³ time
// updates, a rank-one update per row) and a costate sweep. The interior point's solves add
// means-only corrector sweeps of O(M) per row, which the flop model does not count.
// Returns the number of failed instances.
int RunKernelRates(const BenchOptions& options, double gemm20, double gemm40);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_SCALING_REPORT_H_
