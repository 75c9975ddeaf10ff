#ifndef NUPMPC_CORE_MESSAGE_PASSING_SMOOTHER_H_
#define NUPMPC_CORE_MESSAGE_PASSING_SMOOTHER_H_

#include "Eigen/Core"
#include "core/message_passing/forward_filter.h"
#include "core/model/factor_graph.h"

namespace nupmpc::core {

// Posterior means (and optionally variances) of all inputs, rows and x[0] from the
// backward recursion of the modified Bryson–Frazier smoother with input estimation
// ([KL] Table III, re-indexed; nup-algorithms.md §3.2). Runs after RunForwardFilter with
// keep_edges = true on the same factors.
struct SmootherWorkspace {
  Eigen::MatrixXd mU, VU;  ///< L × N posterior of the inputs
  Eigen::VectorXd mY, VY;  ///< per row posterior of cᵀx + d
  Eigen::VectorXd mX0;     ///< posterior mean of x[0]
  Eigen::MatrixXd VX0;     ///< posterior covariance of x[0] (with variances)
  // Scratch.
  Eigen::VectorXd xi, mX, z, Btxi;
  Eigen::MatrixXd W, VX, WV, AtW;

  void Resize(const FactorGraph& graph);
};

// `interrupt` (may be null) is polled once per time step; when it fires the pass returns
// at once with a partial result.
void RunSmootherBackward(const FactorGraph& graph, const ForwardFilterWorkspace& fw, bool with_variances,
                         SmootherWorkspace* ws, Interrupt* interrupt = nullptr);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_MESSAGE_PASSING_SMOOTHER_H_
