#include "core/session/footprint.h"

#include <algorithm>
#include <vector>

#include "Eigen/Core"
#include "core/algorithms/select.h"
#include "core/message_passing/fixed_size.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_factor.h"
#include "core/priors/scalar_prior.h"
#include "core/priors/scalar_rules.h"
#include "core/problem.h"

namespace nupmpc::core {
namespace {

using i64 = std::int64_t;
constexpr i64 kDouble = sizeof(double);

// Eigen pads each of its heap blocks to its alignment, which this build's vector width
// sets (32 bytes with AVX2, 64 with AVX-512): the model counts what this binary allocates.
constexpr i64 kEigenAlignment = EIGEN_MAX_ALIGN_BYTES > 16 ? EIGEN_MAX_ALIGN_BYTES : 16;

// Heap bytes of one block of `bytes`: glibc's chunk header and rounding, Eigen's alignment
// padding (kEigenAlignment over malloc's 16), and for blocks glibc maps (≥ 128 KiB) the
// page rounding.
i64 Block(i64 bytes) {
  if (bytes <= 0) return 0;
  return bytes >= 128 * 1024 ? (bytes + kEigenAlignment + 4095) / 4096 * 4096 + 4096 : bytes + kEigenAlignment + 32;
}
// `count` blocks of `doubles` doubles each.
i64 Doubles(i64 count, i64 doubles) { return count * Block(doubles * kDouble); }
template <typename T>
i64 Array(i64 count) {
  return Block(count * static_cast<i64>(sizeof(T)));
}

struct Dims {
  i64 M, L, K, N, steps;
  i64 nA, nB, nC;
  bool terminal, uncertain;
};

// BuildFactorGraph for a state of Mg (augmented with the inputs or not), as allocated.
i64 GraphBytes(const Dims& d, i64 Mg, bool augmented, i64 rows) {
  const i64 pool_rows = d.nC * d.K + (augmented ? d.L : 0) + (d.terminal ? d.M : 0);
  i64 b = 0;
  b += Array<Eigen::MatrixXd>(d.nA) + Doubles(d.nA, Mg * Mg);
  b += Array<Eigen::MatrixXd>(d.nB) + Doubles(d.nB, Mg * d.L);
  b += 2 * Array<int>(d.N) + Doubles(1, Mg * d.N) + Doubles(1, pool_rows * Mg);
  b += Array<int>(d.N + 2);
  b += 2 * Array<int>(2 * rows) + 2 * Array<RowOrigin>(2 * rows);  // grown by push_back: capacity ≤ 2×
  b += Array<int>(rows) + Array<double>(rows) + Array<ScalarPrior>(rows);
  b += Array<ScalarPrior>(d.N * d.L) + Doubles(1, Mg) + Doubles(1, Mg * Mg);
  return b;
}
// The transient of BuildFactorGraph: the shift map (one tree node per row).
i64 GraphTransient(i64 rows) { return rows * 80; }

struct Parts {
  i64 carried = 0, workspace = 0, transient = 0;
  double flops_per_step = 0.0;
  i64 total() const { return carried + workspace + transient; }
};

i64 GemmScratch(i64 Mg) {
  // Eigen's blocked GEMM for dynamic sizes: packed blocks of at most ~320 × Mg each side.
  if (Mg <= 16) return 0;
  return 2 * Block(std::min<i64>(Mg, 320) * Mg * kDouble) + Block(320 * 320 * kDouble);
}

Parts IakeParts(const Dims& d) {
  const i64 M = d.M, L = d.L, N = d.N, S = d.steps;
  const i64 rows = S * d.K + (d.terminal ? M : 0);
  Parts p;
  p.carried = GraphBytes(d, M, false, rows) + 2 * Array<ScalarFactor>(N * L) + 2 * Array<ScalarFactor>(rows) +
              Array<double>(N * L);
  // Forward filter with kept edges, smoother.
  p.workspace = Doubles(1, M * rows) + Doubles(4, rows) + Doubles(1, M * S) + Doubles(1, M * M * S) +
                Doubles(2, L * N) + Doubles(2, M) + Doubles(2, M * M) + Doubles(1, M * L);
  p.workspace += Doubles(2, L * N) + Doubles(2, rows) + Doubles(1, M) + Doubles(1, M * M) + Doubles(3, M) +
                 Doubles(1, L) + Doubles(4, M * M);
  p.transient = std::max(GraphTransient(rows), GemmScratch(M));
  const double m = static_cast<double>(M), rows_per_step = static_cast<double>(rows) / S;
  // Filter: time update 4M³ + 2M²L, rows 4M² each; smoother with variances 8M³ + rows.
  p.flops_per_step = 12.0 * m * m * m + 2.0 * m * m * L + 6.0 * m * m * rows_per_step + 12.0 * m * L + 8.0 * m * m;
  return p;
}

Parts IbffdParts(const Dims& d) {
  const i64 M = d.M, L = d.L, N = d.N, S = d.steps;
  const i64 rows = S * d.K + (d.terminal ? M : 0);
  Parts p;
  p.carried = GraphBytes(d, M, false, rows) + 2 * Array<ScalarFactor>(N * L) + Array<double>(N * L) +
              3 * Array<Region>(N * L) + Doubles(3, M * M) + Doubles(4, M) + Doubles(1, M * M) + 2 * Array<int>(M);
  // Per step: W's lower triangle, ξ, the prediction's state; per input: its gain record.
  p.workspace = Doubles(1, M * (M + 1) / 2 * S) + Doubles(2, M * S) + Doubles(1, (M + 2) * N * L);
  p.transient = std::max(GraphTransient(rows), GemmScratch(M));
  const double m = static_cast<double>(M), rows_per_step = static_cast<double>(rows) / S;
  // Backward: 4M³ + 4M²L + 2M² per Gaussian row; forward deciding: ~7M²L + 2M².
  p.flops_per_step = 4.0 * m * m * m + 11.0 * m * m * L + 2.0 * m * m * rows_per_step + 6.0 * m * m;
  return p;
}

Parts IffbddParts(const Dims& d, bool inputs_constrained) {
  const bool augmented = inputs_constrained && d.L > 0;
  const i64 Mg = augmented ? PaddedStateSize(static_cast<int>(d.M + d.L)) : d.M;
  const i64 L = d.L, N = d.N, S = d.steps;
  const i64 rows = S * d.K + (augmented ? N * L : 0) + (d.terminal ? d.M : 0);
  Parts p;
  p.carried = GraphBytes(d, Mg, augmented, rows) + Array<ScalarFactor>(N * L) + 2 * Array<ScalarFactor>(rows) +
              Array<double>(rows) + 2 * Array<Region>(rows) + Doubles(2, Mg) + Doubles(1, Mg * S) + Doubles(1, rows) +
              Array<int>(rows) + (augmented ? Array<int>(N * L) : 0);
  p.workspace = Doubles(1, Mg * rows) + Doubles(4, rows) + Doubles(2, L * N) + Doubles(2, Mg) + Doubles(2, Mg * Mg) +
                Doubles(1, Mg * L);
  // The interior-point iteration (no constrained input): per row its sides (two of six
  // doubles), their backups (two of three), its Gaussian part (two), its flag and its
  // Newton value; two plans.
  if (!augmented) {
    p.workspace += Array<unsigned char>(rows) + Doubles(2, 6 * rows) + Doubles(2, 3 * rows) + Doubles(1, 2 * rows) +
                   Doubles(1, rows) + Doubles(2, d.M) + Doubles(2, L * N);
  }
  const double m = static_cast<double>(Mg), rows_per_step = static_cast<double>(rows) / S;
  // Forward: time update 4M³ + 2M²L, rows 4M² each; backward: 2M² + 2M per row.
  p.flops_per_step =
      4.0 * m * m * m + 2.0 * m * m * L + 4.0 * m * m * rows_per_step + 2.0 * m * m + 2.0 * m * rows_per_step;
  p.transient = std::max(GraphTransient(rows), GemmScratch(Mg));
  if (augmented) {
    // The input sub-problem's IBFFD (polish): all of it is scratch, rebuilt after release.
    const Parts input_polish = IbffdParts(d);
    p.workspace += input_polish.carried + input_polish.workspace;
    p.transient = std::max(p.transient, input_polish.transient);
    p.flops_per_step = std::max(p.flops_per_step, input_polish.flops_per_step);
  }
  return p;
}

}  // namespace

Footprint EstimateFootprint(const ProblemShape& s) {
  const i64 M = s.num_states, L = s.num_inputs, K = s.num_outputs, N = s.horizon;
  Dims d{M,
         L,
         K,
         N,
         N + 1,
         s.a_per_step ? N : 1,
         s.b_per_step ? N : 1,
         s.c_per_step ? N + 1 : 1,
         s.terminal_cost,
         s.uncertain_initial_state};
  const i64 S = d.steps;
  Footprint f;
  // The Problem.
  const i64 n_state_offsets = s.offsets_per_step ? N : 1, n_output_offsets = s.offsets_per_step ? S : 1;
  f.problem_bytes = Array<Eigen::MatrixXd>(d.nA) + Doubles(d.nA, M * M) + Array<Eigen::MatrixXd>(d.nB) +
                    Doubles(d.nB, M * L) + Array<Eigen::MatrixXd>(d.nC) + Doubles(d.nC, K * M) +
                    Array<Eigen::VectorXd>(n_state_offsets) + Doubles(n_state_offsets, M) +
                    Array<Eigen::VectorXd>(n_output_offsets) + Doubles(n_output_offsets, K) + Doubles(1, M) +
                    (s.uncertain_initial_state ? Doubles(1, M * M) : 0) + Array<ScalarPrior>(N * L) +
                    Array<ScalarPrior>(S * K) + (s.terminal_cost ? Doubles(1, M) + Doubles(1, M * M) : 0);

  // The algorithm: the one given, else the largest of all.
  std::vector<Parts> candidates;
  if (s.algorithm == Algorithm::kAuto || s.algorithm == Algorithm::kIake) candidates.push_back(IakeParts(d));
  if (s.algorithm == Algorithm::kAuto || s.algorithm == Algorithm::kIbffd) candidates.push_back(IbffdParts(d));
  if (s.algorithm == Algorithm::kAuto || s.algorithm == Algorithm::kIffbdd) {
    candidates.push_back(IffbddParts(d, s.inputs_constrained));
  }
  Parts a;
  for (const Parts& c : candidates) {
    a.carried = std::max(a.carried, c.carried);
    a.workspace = std::max(a.workspace, c.workspace);
    a.transient = std::max(a.transient, c.transient);
    a.flops_per_step = std::max(a.flops_per_step, c.flops_per_step);
  }

  // The session: objective trajectories, three primal iterates, the hard-bound list, and
  // one Solution as Solve() fills it.
  const i64 session = Doubles(1, M * S) + Doubles(1, K * S) + Doubles(2, M) +
                      (s.uncertain_initial_state ? Doubles(1, M * M) : 0) + 3 * (Doubles(1, M) + Doubles(1, L * N)) +
                      Array<int>(S * K) + Doubles(1, N * L) + Doubles(1, S * M) + Doubles(1, S * K) + 4096;
  // Create's transients: the terminal weight's eigen-decomposition (RefreshFactorGraph).
  const i64 eigen = s.terminal_cost ? Doubles(3, M * M) + Doubles(6, M) : 0;
  f.carried_bytes = a.carried + session;
  f.workspace_bytes = a.workspace;
  f.transient_bytes = std::max(a.transient, eigen);
  f.flops_per_step = a.flops_per_step + 2.0 * static_cast<double>(M) * (M + L + K);  // + the objective
  f.flops_per_pass = f.flops_per_step * static_cast<double>(S);
  return f;
}

ProblemShape ShapeOf(const Problem& p, Algorithm requested) {
  ProblemShape s;
  s.num_states = p.num_states;
  s.num_inputs = p.num_inputs;
  s.num_outputs = p.num_outputs;
  s.horizon = p.horizon;
  s.a_per_step = p.A.size() > 1;
  s.b_per_step = p.B.size() > 1;
  s.c_per_step = p.C.size() > 1;
  s.uncertain_initial_state = !p.initial_state_fixed();
  s.terminal_cost = p.terminal.has_value();
  s.offsets_per_step = p.state_offset.size() > 1 || p.output_offset.size() > 1;
  const absl::StatusOr<Algorithm> selected = SelectAlgorithm(p, requested);
  s.algorithm = selected.ok() ? *selected : Algorithm::kAuto;
  s.inputs_constrained = std::any_of(p.input_priors.begin(), p.input_priors.end(),
                                     [](const ScalarPrior& prior) { return prior.kind != PriorKind::kNone; });
  return s;
}

}  // namespace nupmpc::core
