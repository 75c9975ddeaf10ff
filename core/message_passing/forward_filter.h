#ifndef NUPMPC_CORE_MESSAGE_PASSING_FORWARD_FILTER_H_
#define NUPMPC_CORE_MESSAGE_PASSING_FORWARD_FILTER_H_

#include <vector>

#include "Eigen/Core"
#include "absl/functional/function_ref.h"
#include "core/algorithms/interrupt.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_factor.h"

namespace nupmpc::core {

// Storage of the forward Kalman filter with sequential scalar updates
// (nup-algorithms.md §3.1). Sized once for a graph; the filter never allocates.
struct ForwardFilterWorkspace {
  // Per row r, the values before the row's factor is applied.
  Eigen::MatrixXd v;     ///< M × R: v = V c
  Eigen::VectorXd s;     ///< cᵀ V c (prior variance of the row's output)
  Eigen::VectorXd yhat;  ///< cᵀ m + d (prior mean)
  Eigen::VectorXd G, g;  ///< gain terms; 0 when the row carried no factor or was skipped
  // Post-update edges per step (only when requested; the MBF smoother needs them).
  Eigen::MatrixXd m_post;  ///< M × (N+1)
  Eigen::MatrixXd V_post;  ///< M × M(N+1), block n at columns [nM, nM+M)
  // Input factors in moment form for the time update (per input scalar).
  Eigen::MatrixXd mU, VU;  ///< L × N
  // Scratch.
  Eigen::VectorXd m, t;
  Eigen::MatrixXd V, AV, BD;

  void Resize(const FactorGraph& graph, bool keep_edges);
};

// Runs the filter with the given scalar factors: `input_factor` (N·L, must have a moment
// form: Gaussian inputs) and `row_factor` (one per row; empty factors are skipped).
// Degenerate rows (prior variance ≈ 0 with a pinned factor, §12.2) are skipped.
// `interrupt` (may be null) is polled once per time step (interrupt.h); when it fires the
// filter returns at once and the workspace holds a partial pass.
void RunForwardFilter(const FactorGraph& graph, const ScalarFactor* input_factor, const ScalarFactor* row_factor,
                      bool keep_edges, ForwardFilterWorkspace* ws, Interrupt* interrupt = nullptr);

// As RunForwardFilter (inputs as loaded last), but the factor of every row with a
// constraint kind is chosen when the filter reaches it, from the row's prediction before
// its own factor: decide(row, ŷ, s, v) with v = V c (M values). Rows of kind kNone take
// row_factor[row]. The active-set polish uses it to decide a row's region knowing the rows
// before it in this same pass (a forward Gauss-Seidel sweep).
using RowDecider = absl::FunctionRef<ScalarFactor(int row, double yhat, double s, const double* v)>;
void RunForwardFilterDeciding(const FactorGraph& graph, const ScalarFactor* row_factor, RowDecider decide,
                              ForwardFilterWorkspace* ws, Interrupt* interrupt = nullptr);

// The means of RunForwardFilter again for new row factors with the same precisions: only
// ξ of canonical factors may differ from the last full pass (whose v, s, G it reuses), so
// the gains are the same and only the O(M) per row and O(M²) per step of the means
// remain, against O(M²) and O(M³) of the full filter. Rewrites ŷ and g; an interior-point
// method's corrector solves the same Newton system for a second right-hand side with it.
// Row factors must be canonical (V = ∞) or empty, as in that full pass; a row with an
// empty factor gets its ŷ and no update (g = 0) whatever its prior (the priors are not
// read, which long horizons would stream for nothing).
void RunForwardMeans(const FactorGraph& graph, const ScalarFactor* row_factor, ForwardFilterWorkspace* ws,
                     Interrupt* interrupt = nullptr);

// Writes the moment form of the input factors into ws->mU / ws->VU. Separate because
// IFFBDD's inputs stay fixed across iterations.
void LoadInputMoments(const FactorGraph& graph, const ScalarFactor* input_factor, ForwardFilterWorkspace* ws);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_MESSAGE_PASSING_FORWARD_FILTER_H_
