#ifndef NUPMPC_CORE_ALGORITHMS_IBFFD_H_
#define NUPMPC_CORE_ALGORITHMS_IBFFD_H_

#include <vector>

#include "absl/status/status.h"
#include "core/algorithms/ibffd_policy.h"
#include "core/algorithms/outer_iteration.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

// IBFFD ([LL-BFFD] Alg. 1; nup-algorithms.md §8): backward information filter over the
// NUP Gaussians of the inputs, then forward deciding of every scalar input from its
// extrinsic message with the exact proximal rule; hard constraints adapt their slope
// (§8.3), so every iterate is feasible. Outputs may only carry Gaussian priors.
//
// The passes and the policy carried for the warm start's polish are IbffdPolicy's; this
// class adds the NUP state the iteration carries (NUP factors, adapted slopes, regions).
class Ibffd final : public ActiveSetIteration {
 public:
  static absl::Status CheckApplicable(const Problem& problem);
  Ibffd(const Problem& problem, const SolverOptions& options);

  Algorithm algorithm() const override { return Algorithm::kIbffd; }
  void set_interrupt(Interrupt* interrupt) override {
    OuterIteration::set_interrupt(interrupt);
    policy_.set_interrupt(interrupt);
  }
  void Refresh(const Problem& problem) override { policy_.Refresh(problem); }
  void RefreshInitialState(const Problem& problem) override { policy_.RefreshInitialState(problem); }
  void ColdStart() override;
  void ShiftWarmStart() override;
  int Iterate(PrimalIterate* out) override;
  double Polish(PrimalIterate* out) override { return policy_.Polish(&polish_region_, out); }
  void AdoptRegionsForPolish() override;
  void AdoptCarriedRegionsForPolish() override;
  void ReleaseWorkspace() override { policy_.ReleaseWorkspace(); }
  void AcquireWorkspace(const Problem& /*problem*/) override { policy_.AcquireWorkspace(); }
  void PersistState(StateArchive& archive, const Problem& problem) override;

 private:
  double InitialSlope(const ScalarPrior& prior) const;

  SolverOptions options_;
  IbffdPolicy policy_;
  std::vector<ScalarFactor> nup_;  ///< NUP part per input (the carried state)
  std::vector<double> slope_;      ///< adapted slope per input
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IBFFD_H_
