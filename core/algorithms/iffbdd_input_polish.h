#ifndef NUPMPC_CORE_ALGORITHMS_IFFBDD_INPUT_POLISH_H_
#define NUPMPC_CORE_ALGORITHMS_IFFBDD_INPUT_POLISH_H_

#include <memory>
#include <vector>

#include "core/algorithms/ibffd_policy.h"
#include "core/algorithms/interrupt.h"
#include "core/algorithms/primal_iterate.h"
#include "core/model/factor_graph.h"
#include "core/options.h"
#include "core/priors/scalar_rules.h"
#include "core/problem.h"

namespace nupmpc::core {

// IFFBDD's polish on the input sub-problem (Iffbdd::AdoptCarriedRegionsForPolish): an
// IbffdPolicy with check_outputs on the problem without its output constraints, used when
// some input is constrained and every output prior is a box or half-space, and its regions
// of the input scalars (n·L + l), which map to rows of IFFBDD's augmented graph.
//
// The policy is scratch: Release destroys it (most of an idle session's memory) and keeps
// only its policy's memory; Acquire rebuilds it from the problem.
class IffbddInputPolish {
 public:
  // Whether the problem gets it: some input constrained (the graph is augmented with the
  // input rows), no output prior L1 (the sub-problem needs output kinds whose inside costs
  // nothing) and the polish enabled.
  IffbddInputPolish(const Problem& problem, const FactorGraph& graph, bool inputs_constrained,
                    const SolverOptions& options);

  // Whether it is there now (used, and its workspace held).
  bool active() const { return policy_ != nullptr; }

  void set_interrupt(Interrupt* interrupt) {
    if (policy_) policy_->set_interrupt(interrupt);
  }
  void Refresh(const Problem& problem) {
    if (policy_) policy_->Refresh(problem);
  }
  void RefreshInitialState(const Problem& problem) {
    if (policy_) policy_->RefreshInitialState(problem);
  }
  // A cold start: the carried policy, live or released, is gone.
  void ColdStart();
  // The sub-problem's carried policy belongs to an older active set now.
  void ForgetPolicy() {
    if (policy_) policy_->Forget();
  }
  // Receding horizon: the carried policy, live or released, moves one step earlier.
  void Shift();
  void Release();
  void Acquire(const Problem& problem, Interrupt* interrupt);
  // Snapshots (core/snapshot/algorithm_state.cc): the carried policy, live or released.
  // Its workspace must already be held or released as in the saved one (Iffbdd's).
  void PersistState(StateArchive& archive);

  // Starts a polish on the sub-problem from `region`'s input rows (active() only).
  void Start(const std::vector<Region>& region, bool carried);
  // One polish pass; its residual (IbffdPolicy::Polish).
  double Polish(PrimalIterate* out) { return policy_->Polish(&region_, out); }
  // The last pass (not accepted) left an output outside its bounds.
  bool outputs_outside() const { return policy_->outputs_outside(); }
  // IFFBDD's regions as the sub-problem proposes them: its input rows', outputs inside.
  void ProposedRegions(std::vector<Region>* region) const;

 private:
  const bool used_;
  std::unique_ptr<IbffdPolicy> policy_;
  std::vector<Region> region_;  ///< of the input scalars
  IbffdPolicy::Memory released_;
  std::vector<int> input_row_;  ///< the augmented row of input scalar n·L + l
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IFFBDD_INPUT_POLISH_H_
