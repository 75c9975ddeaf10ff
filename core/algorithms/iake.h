#ifndef NUPMPC_CORE_ALGORITHMS_IAKE_H_
#define NUPMPC_CORE_ALGORITHMS_IAKE_H_

#include <vector>

#include "absl/status/status.h"
#include "core/algorithms/outer_iteration.h"
#include "core/message_passing/forward_filter.h"
#include "core/message_passing/smoother.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

// IAKE / IRLGE ([KL]; nup-algorithms.md §6): Gaussian smoothing (forward filter + MBF
// backward) with the current NUP Gaussians, then the closed-form NUP update of every
// prior at the posterior means. The general fallback: any prior on inputs and outputs.
// Hard constraints are replaced by the exact penalty with slope
// SolverOptions.iake_hard_slope (it must exceed the constraint's multiplier, §6.2).
// It does not track active sets, so it is never polished.
class Iake final : public OuterIteration, public InputPinning {
 public:
  static absl::Status CheckApplicable(const Problem& problem);
  Iake(const Problem& problem, const SolverOptions& options);

  Algorithm algorithm() const override { return Algorithm::kIake; }
  void Refresh(const Problem& problem) override;
  void RefreshInitialState(const Problem& problem) override { RefreshFactorGraphInitialState(problem, &graph_); }
  void ColdStart() override;
  void ShiftWarmStart() override;
  int Iterate(PrimalIterate* out) override;
  void AdoptRegionsForPolish() override {}
  void AcceptPolishRegions() override {}
  double Polish(PrimalIterate*) override { return kInfinity; }
  bool has_regions() const override { return false; }
  InputPinning* input_pinning() override { return this; }
  void PinInput(int index, double value) override { pinned_value_[index] = value; }
  void ReleaseInputPins() override;
  void ReleaseWorkspace() override;
  void AcquireWorkspace(const Problem& problem) override;
  void PersistState(StateArchive& archive, const Problem& problem) override;

 private:
  double EffectiveSlope(const ScalarPrior& prior) const {
    return prior.is_hard() ? options_.iake_hard_slope : prior.slope;
  }
  ScalarFactor Update(const ScalarPrior& prior, double estimate, double posterior_variance) const;
  // What Refresh() derives from the graph's priors (variance floor, EM variances).
  void RefreshDerived();

  SolverOptions options_;
  FactorGraph graph_;
  ForwardFilterWorkspace fw_;  ///< scratch of every pass (released while idle)
  SmootherWorkspace sm_;       ///< scratch of every pass
  bool workspace_held_ = false;
  std::vector<ScalarFactor> input_nup_, row_nup_;        ///< carried NUP parts
  std::vector<ScalarFactor> input_factor_, row_factor_;  ///< with Gaussian parts
  std::vector<double> pinned_value_;                     ///< per input scalar: NaN, or the value it is pinned to
  double variance_floor_ = 0.0;
  bool needs_variances_ = false;  ///< an EM prior is present: the smoother computes variances
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IAKE_H_
