#ifndef NUPMPC_CORE_ALGORITHMS_IBFFD_H_
#define NUPMPC_CORE_ALGORITHMS_IBFFD_H_

#include <vector>

#include "Eigen/LU"
#include "absl/status/status.h"
#include "core/algorithms/outer_iteration.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

// IBFFD ([LL-BFFD] Alg. 1; nup-algorithms.md §8): backward information filter over the
// NUP Gaussians of the inputs, then forward deciding of every scalar input from its
// extrinsic message with the exact proximal rule; hard constraints adapt their slope
// (§8.3), so every iterate is feasible. Outputs may only carry Gaussian priors.
//
// Memory: the backward message (W, ξ) at each state x[n] (N·M² doubles); the per-input
// messages inside a step are recomputed in the forward pass (§8.5 alternative).
class Ibffd final : public ActiveSetIteration {
 public:
  static absl::Status CheckApplicable(const Problem& problem);
  Ibffd(const Problem& problem, const SolverOptions& options);

  Algorithm algorithm() const override { return Algorithm::kIbffd; }
  void Refresh(const Problem& problem) override;
  void RefreshInitialState(const Problem& problem) override { RefreshFactorGraphInitialState(problem, &graph_); }
  void ColdStart() override;
  void ShiftWarmStart() override;
  int Iterate(PrimalIterate* out) override;
  double Polish(PrimalIterate* out) override;
  void ReleaseWorkspace() override;
  void AcquireWorkspace() override;

 private:
  enum class Pass { kIterate, kPolish };
  void BackwardFilter(const std::vector<ScalarFactor>& input_factor);
  double ForwardDeciding(Pass pass, PrimalIterate* out);
  template <int MS>
  void BackwardFilterImpl(const std::vector<ScalarFactor>& input_factor);
  template <int MS>
  double ForwardDecidingImpl(Pass pass, PrimalIterate* out);
  double InitialSlope(const ScalarPrior& prior) const;

  SolverOptions options_;
  FactorGraph graph_;
  std::vector<ScalarFactor> nup_;        ///< NUP part per input (the carried state)
  std::vector<ScalarFactor> factor_;     ///< what the backward filter sees
  std::vector<double> slope_;            ///< adapted slope per input
  // Scratch of every pass (released while idle).
  Eigen::MatrixXd W_step_;   ///< M × M(N+1): backward message at x[n] (before step n-1's inputs)
  Eigen::MatrixXd xi_step_;  ///< M × (N+1)
  Eigen::MatrixXd W_, AtW_, S_;
  Eigen::VectorXd xi_, z_, x_, rhs_;
  Eigen::MatrixXd D_;        ///< M × M·L: per-input messages inside one step (forward pass)
  Eigen::MatrixXd d_;        ///< M × L
  Eigen::PartialPivLU<Eigen::MatrixXd> x0_lu_;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IBFFD_H_
