#ifndef NUPMPC_CORE_ALGORITHMS_IBFFD_POLICY_H_
#define NUPMPC_CORE_ALGORITHMS_IBFFD_POLICY_H_

#include <vector>

#include "Eigen/LU"
#include "core/algorithms/interrupt.h"
#include "core/algorithms/primal_iterate.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_factor.h"
#include "core/priors/scalar_rules.h"
#include "core/problem.h"

namespace nupmpc::core {

class StateArchive;  // core/snapshot/state_archive.h

// IBFFD's passes over one factor graph ([LL-BFFD] Alg. 1; nup-algorithms.md §8) and the
// policy they carry: the backward information filter over the inputs' factors, then
// forward deciding of every scalar input from its extrinsic message with the exact
// proximal rule. Used by Ibffd (the whole algorithm) and by Iffbdd (the warm polish on its
// input sub-problem), which differ only in the state they carry around these passes.
//
// The policy: the backward messages (W, ξ) at each state x[n] of the last active-set pass
// are the optimal affine policy of that active set (u = prox of the extrinsic message at
// the state reached). They do not depend on x[0], and shifted by one step they are exact
// except near the tail, so they are carried between solves (not only the NUP state §10
// lists). The first polish pass of a warm solve predicts the new active set with them
// before it solves: (0) the policy's offsets ξ from the current references and bounds (its
// gains W depend on neither; no M³ work), (1) a forward sweep from the new x[0] that
// decides every input with the carried policy (no M³ work either), (2) the backward
// filter, deciding each input from the state predicted in (1) as it reaches it, (3) the
// usual forward pass with the decided regions. Counted as one pass: (0) and (1) add sweeps
// of matrix-vector products, no M³ work. Every polish pass propagates the decided input
// (Gauss-Seidel) rather than the polish factor's, so each region decision sees the earlier
// decisions of the pass.
//
// Memory: the backward message at each state (N·M² doubles, released while idle); the
// per-input messages inside a step are recomputed in the forward pass (§8.5 alternative).
// Passes allocate nothing.
class IbffdPolicy {
 public:
  // `check_outputs`: the graph is IFFBDD's input sub-problem, the problem without its
  // output constraints (outputs act through their Gaussian parts only; their kinds must
  // be box or half-space or none). A polish pass then also reports, in its residual, how
  // far any constrained output lies outside its kinks, so a residual within tolerance
  // means the candidate solves the full problem: the output constraints are inactive with
  // zero multipliers.
  IbffdPolicy(const Problem& problem, bool check_outputs);

  const FactorGraph& graph() const { return graph_; }
  void Refresh(const Problem& problem);
  void RefreshInitialState(const Problem& problem) { RefreshFactorGraphInitialState(problem, &graph_); }
  // Polled by every pass (null: none); not owned.
  void set_interrupt(Interrupt* interrupt) { interrupt_ = interrupt; }

  // What the NUP iteration carries per input scalar (Ibffd): the NUP factors, the adapted
  // slopes of hard constraints (§8.3) and the region each input was decided in.
  struct NupState {
    std::vector<ScalarFactor>* nup;
    std::vector<double>* slope;
    std::vector<Region>* region;
  };
  // One NUP iteration: the filter over the NUP factors, then deciding every input with the
  // adaptive-slope rule and updating `state`. Returns how many inputs changed region, or
  // -1 if interrupted before deciding (the state is untouched then). Drops the policy:
  // the NUP iterate's messages are no policy of an active set.
  int Iterate(NupState state, PrimalIterate* out);

  // Arms the next Polish(): a `carried` start (a warm solve's first polish) predicts the
  // active set with the carried policy, if there is one.
  void StartPolish(bool carried) { predict_next_ = carried && has_policy_; }
  // Active-set polish: solves with every input restricted to its region in
  // `polish_region`, writes the candidate and returns the deciding residual (kInfinity if
  // interrupted); `polish_region` becomes the regions the deciding rule proposes. The
  // filter's messages become the carried policy.
  double Polish(std::vector<Region>* polish_region, PrimalIterate* out);
  // Whether the last polish pass found a constrained output outside its kinks
  // (check_outputs only): the input sub-problem is then the wrong problem.
  bool outputs_outside() const { return outputs_outside_; }

  // Forgets the policy (cold start).
  void Forget() { has_policy_ = policy_released_ = false; }
  // Receding horizon: the policy moves one step earlier with its regions.
  void Shift() {
    if (has_policy_) ShiftPolicy(1);
    if (has_policy_ || policy_released_) ++policy_shifts_;
  }

  // Idle: frees the per-step messages (the policy remembers only what it integrated).
  void ReleaseWorkspace();
  // Gets them back and recomputes a released policy (a backward pass; polls the interrupt).
  void AcquireWorkspace();
  // Snapshots (core/snapshot/algorithm_state.cc): the policy, live or released, and
  // whether the workspace is held.
  void PersistState(StateArchive& archive);

  // What of the policy survives this object (Iffbdd drops its input polish while idle and
  // rebuilds it): the regions its filter integrated and the shifts since.
  struct Memory {
    std::vector<Region> regions;
    int shifts = 0;
    bool valid = false;
  };
  Memory TakeMemory();
  // On a freshly built object of the same problem: recomputes that policy (allocates).
  void RestoreMemory(Memory memory);

 private:
  enum class Pass {
    kIterate,  ///< NUP iteration: decide with the adapted slopes, update the NUP factors
    kPredict,  ///< warm start (1): decide with the carried policy, record the states
    kPolish,   ///< active-set polish: decide, report the residual, propose regions
  };
  enum class Sweep {
    kFull,      ///< the backward information filter over factor_
    kDeciding,  ///< the same, deciding every constrained input when the filter reaches it,
                ///< from the state the prediction sweep recorded (x_pred_, and `predicted`
                ///< for the inputs of the same step); its factor and polish region become
                ///< the decided piece before it is integrated out
    kOffsets,   ///< only ξ, with the stored W (the carried gains): O(N L M²), no M³ work
  };
  // Where a pass writes its decisions: the NUP state (kIterate) or the polish regions.
  struct Targets {
    NupState nup{nullptr, nullptr, nullptr};
    std::vector<Region>* polish_region = nullptr;
  };
  bool Interrupted() const { return interrupt_ != nullptr && interrupt_->fired(); }
  // factor_[i] = the piece of input i's prior in regions[i].
  void LoadPieceFactors(const std::vector<Region>& regions);
  // factor_ = the pieces the carried policy integrated, at their shifted steps.
  void LoadShiftedPolicyFactors();
  void BackwardFilter(Sweep sweep, const Targets& targets, const PrimalIterate* predicted = nullptr);
  double ForwardDeciding(Pass pass, const Targets& targets, PrimalIterate* out);
  template <int MS>
  void BackwardFilterImpl(Sweep sweep, const Targets& targets, const PrimalIterate* predicted);
  template <int MS>
  double ForwardDecidingImpl(Pass pass, const Targets& targets, PrimalIterate* out);
  // row_term_ and row_bound_ from the graph's rows.
  void RefreshRowTerms();
  // Largest distance of a constrained output row of step n outside its kinks at state x.
  template <typename XT>
  double OutputsOutside(int n, const XT& x) const;
  void ShiftPolicy(int steps);
  // The per-step messages' storage (AcquireWorkspace without recomputing the policy).
  void AllocateWorkspace();
  // The backward filter over policy_region_, shifted policy_shifts_ times.
  void RecomputePolicy();

  FactorGraph graph_;
  bool check_outputs_ = false;
  bool outputs_outside_ = false;
  Interrupt* interrupt_ = nullptr;
  std::vector<ScalarFactor> factor_;  ///< what the backward filter sees
  // What the sweeps read of each row's prior, packed (the priors themselves are several
  // times larger and would be streamed through every pass of a long horizon).
  struct RowTerm {
    double w = 0.0;   ///< Gaussian part's precision (0: none)
    double xi = 0.0;  ///< its precision-mean, less w·d (the row's offset)
  };
  struct RowBound {
    double lower = -kInfinity;  ///< the kinks a polish candidate's output must lie within
    double upper = kInfinity;
  };
  std::vector<RowTerm> row_term_;
  std::vector<RowBound> row_bound_;
  // Scratch of every pass (released while idle); W_step_/xi_step_ double as the carried
  // policy while has_policy_. The forward pass reads only input_gain_ (and W_step_ at
  // x[0]): what it needs of each input's message, in the order it needs it.
  Eigen::MatrixXd W_step_;      ///< M(M+1)/2 × (N+1): backward message W at x[n] (before step
                                ///< n-1's inputs), its lower triangle (PackLower)
  Eigen::MatrixXd xi_step_;     ///< M × (N+1)
  Eigen::MatrixXd input_gain_;  ///< (M+2) × N·L: per input, with the step's later inputs
                                ///< integrated out, z = W b, bᵀz and bᵀξ (RecordInput);
                                ///< written by every backward sweep for the forward pass
                                ///< after it, so not part of the carried policy
  Eigen::MatrixXd x_pred_;      ///< M × (N+1): states of the warm start's prediction sweep
  bool has_policy_ = false;
  // The regions the policy's backward filter integrated, and how often it was shifted
  // since. ReleaseWorkspace drops the policy; AcquireWorkspace recomputes it from these:
  // the same gains W while weights and matrices are unchanged (references and bounds may
  // change: every warm solve recomputes the offsets ξ from the current data anyway), so a
  // released session continues bit-identically (tested). After new weights or matrices the
  // recomputed gains are the new ones: the same optimum, possibly another number of passes.
  std::vector<Region> policy_region_;
  int policy_shifts_ = 0;
  bool policy_released_ = false;
  bool predict_next_ = false;
  Eigen::MatrixXd W_, AtW_, S_;
  Eigen::VectorXd xi_, z_, x_, rhs_;
  Eigen::PartialPivLU<Eigen::MatrixXd> x0_lu_;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IBFFD_POLICY_H_
