#ifndef NUPMPC_CORE_MODEL_FACTOR_GRAPH_H_
#define NUPMPC_CORE_MODEL_FACTOR_GRAPH_H_

#include <vector>

#include "Eigen/Core"
#include "core/priors/scalar_prior.h"
#include "core/problem.h"

namespace nupmpc::core {

using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Where a scalar factor row of the graph comes from.
struct RowOrigin {
  enum class Type : std::uint8_t { kOutput, kInput, kTerminal };
  Type type;
  int step;   ///< step n of the output / input (for kInput: the input's own step n-1)
  int index;  ///< k, l, or the terminal row i
};

// The problem as the message passing sees it (nup-algorithms.md §2): per step the
// matrices A, B (shared through pools when time-invariant) and a list of scalar factor
// rows y = cᵀx + d, each with its prior. Output rows, terminal rows (Qf = Σ λ q qᵀ as
// rows √λ qᵀ with unit Gaussians) and, for IFFBDD, augmented input rows (§9.6: the state
// carries the last input, so u[n] is the row e_{M+l} at step n+1).
//
// Built once per session shape (allocates); Refresh() copies new values of the same
// shape into it without allocating.
struct FactorGraph {
  int M = 0;       ///< state dimension (M + L when augmented, padded: PaddedStateSize)
  int L = 0;       ///< inputs per step
  int N = 0;       ///< horizon
  int base_M = 0;  ///< the problem's M
  bool augmented = false;

  std::vector<Eigen::MatrixXd> A_pool, B_pool;
  std::vector<int> a_of, b_of;  ///< pool index per step (size N)
  Eigen::MatrixXd cx;           ///< M × N state offsets (zero when none)

  RowMajorMatrix c_pool;       ///< rows cᵀ; row_c[r] indexes into it
  std::vector<int> row_begin;  ///< rows of step n are [row_begin[n], row_begin[n+1]); size N+2
  std::vector<int> row_c;
  std::vector<int> row_unit;  ///< i if the row's c is the unit vector e_i, else -1
  std::vector<double> row_d;
  std::vector<ScalarPrior> row_prior;
  std::vector<RowOrigin> row_origin;
  std::vector<int> row_shift_source;  ///< the row at step n+1 with the same origin (or itself)

  std::vector<ScalarPrior> input_prior;  ///< N·L; augmented: only the Gaussian part remains here

  Eigen::VectorXd m0;  ///< initial mean (size M)
  Eigen::MatrixXd V0;  ///< initial covariance (M×M, zero when fixed)
  bool x0_fixed = true;

  int num_rows() const { return static_cast<int>(row_c.size()); }
  const Eigen::MatrixXd& A(int n) const { return A_pool[a_of[n]]; }
  const Eigen::MatrixXd& B(int n) const { return B_pool[b_of[n]]; }
  auto c(int r) const { return c_pool.row(row_c[r]).transpose(); }
  const ScalarPrior& input(int n, int l) const { return input_prior[n * L + l]; }
};

// Builds the graph. `augment_inputs` moves every input's non-Gaussian part to an
// augmented row (IFFBDD); it requires each such input to have a Gaussian part.
FactorGraph BuildFactorGraph(const Problem& problem, bool augment_inputs);

// Copies the values of a problem of the same shape into an existing graph
// (no allocation). The caller guarantees the shape matches the one built.
void RefreshFactorGraph(const Problem& problem, FactorGraph* graph);
// Only the output rows' priors (no allocation).
void RefreshFactorGraphOutputPriors(const Problem& problem, FactorGraph* graph);

// Copies only x[0]'s mean (the per-step measurement). No allocation.
inline void RefreshFactorGraphInitialState(const Problem& problem, FactorGraph* graph) {
  graph->m0.head(problem.num_states) = problem.initial_mean;
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_MODEL_FACTOR_GRAPH_H_
