#ifndef NUPMPC_CORE_ALGORITHMS_OUTER_ITERATION_H_
#define NUPMPC_CORE_ALGORITHMS_OUTER_ITERATION_H_

#include <vector>

#include "Eigen/Core"
#include "core/algorithms/interrupt.h"
#include "core/algorithms/primal_iterate.h"
#include "core/options.h"
#include "core/priors/scalar_rules.h"
#include "core/problem.h"

namespace nupmpc::core {

class StateArchive;  // core/snapshot/state_archive.h

// Sequential rounding of binary inputs (SolverOptions.discrete_fixing_passes): pins input
// scalar `index` (n·L + l) to `value` in the following passes, and releases all pins. Only
// IAKE runs binary priors, so only it offers pins (OuterIteration::input_pinning()).
class InputPinning {
 public:
  virtual void PinInput(int index, double value) = 0;
  virtual void ReleaseInputPins() = 0;

 protected:
  ~InputPinning() = default;
};

// One NUP algorithm: its graph, its workspace and the per-scalar state it carries between
// iterations and between solves (the warm start). The solve loop (stopping, limits,
// polish scheduling, objective evaluation) lives in the driver, not here.
//
// Contract: construction allocates everything; Iterate(), Polish(), ShiftWarmStart()
// and ColdStart() never allocate.
//
// Interruption (interrupt.h): while an Interrupt is set, every per-step loop of Iterate(),
// Polish() and AcquireWorkspace() polls it and returns early once it fired. The pass is
// then incomplete: its output iterate is garbage and so may be the carried state it was
// updating; the driver must discard the iterate and ColdStart() before the next pass.
class OuterIteration {
 public:
  virtual ~OuterIteration() = default;
  virtual Algorithm algorithm() const = 0;

  // The interrupt the passes poll (null: none). Not owned; the driver clears it before
  // the object it points to goes away.
  virtual void set_interrupt(Interrupt* interrupt) { interrupt_ = interrupt; }

  // Copies new values (same shape) of the problem into the graph (x0, references, bounds,
  // matrices). Keeps the carried NUP state.
  virtual void Refresh(const Problem& problem) = 0;
  // Cheaper Refresh for the common per-step update: only x[0]'s mean changed. No allocation.
  virtual void RefreshInitialState(const Problem& problem) = 0;
  // Cheaper Refresh when only the output priors' kind parts changed (the session's elastic
  // fallback changes slopes). IFFBDD's needs no allocation; others refresh everything.
  virtual void RefreshOutputPriors(const Problem& problem) { Refresh(problem); }
  // Forgets the carried state: the next Iterate() starts from the papers' initialisation.
  virtual void ColdStart() = 0;
  // Receding horizon: the state of step n+1 becomes the state of step n; the last step
  // keeps its own (nup-algorithms.md §10).
  virtual void ShiftWarmStart() = 0;

  // One message-passing pass plus NUP updates. Writes the primal iterate and returns how
  // many scalars changed region (active set) since the previous pass, or -1 if the
  // algorithm does not track regions.
  virtual int Iterate(PrimalIterate* out) = 0;

  // Active-set polish: freezes the regions seen in the last Iterate() (or the carried ones).
  virtual void AdoptRegionsForPolish() = 0;
  // The same for the regions carried from the previous solve (the warm start's first
  // polish), where the algorithm may also use the carried duals.
  virtual void AdoptCarriedRegionsForPolish() { AdoptRegionsForPolish(); }
  // Solves the problem with every scalar restricted to its polish region (kinks pinned,
  // smooth pieces Gaussian/linear) with one exact message-passing pass, writes that
  // candidate, and returns the deciding-rule residual max |prox(κ; m_e, V_e) - z|: zero
  // (to rounding) iff the candidate is optimal. Afterwards the polish regions are the
  // ones the true deciding rule chose (a primal-dual active-set correction).
  virtual double Polish(PrimalIterate* out) = 0;
  // The last polish was accepted: its (verified) regions become the carried state, so a
  // warm restart from the optimum polishes once and is done.
  virtual void AcceptPolishRegions() = 0;
  // Whether regions from a previous solve are available (a warm polish is worth trying).
  virtual bool has_regions() const = 0;
  // Whether a polish started now would solve an input sub-problem only (Iffbdd): the driver
  // then starts it at SolverOptions.input_polish_settled_fraction.
  virtual bool NextPolishSolvesInputsOnly() const { return false; }
  // How many scalars the active set covers (0 when the algorithm tracks none).
  virtual int decided_scalars() const { return 0; }
  // Dual methods (IFFBDD): the largest |multiplier| of a constrained row in the last
  // Iterate(). An empty constraint set makes the dual unbounded: this grows without bound
  // while the violation does not fall (core/session/infeasibility.h). 0 for the others.
  virtual double largest_dual() const { return 0.0; }

  // The algorithm's input pins (InputPinning), or null if it has none.
  virtual InputPinning* input_pinning() { return nullptr; }

  // Idle sessions: frees the message-passing scratch (everything every pass recomputes;
  // the carried state and the graph stay), which is most of a session's memory.
  virtual void ReleaseWorkspace() = 0;
  // Gets it back (allocates; a no-op when held) for `problem`, the session's current
  // problem (an algorithm may rebuild released parts from it). The driver calls it before
  // the iteration loop; Iterate() and Polish() need it.
  virtual void AcquireWorkspace(const Problem& problem) = 0;

  // Snapshots (core/snapshot/algorithm_state.cc): saves or restores what the next solves
  // read of the carried state, and whether the workspace is held (a released one is
  // rebuilt from the carried state on acquiring: a restore releases too, so the rebuild
  // happens as in the original). A restore comes after Refresh(problem) with the
  // session's restored values, so it overwrites what Refresh derives from them.
  virtual void PersistState(StateArchive& archive, const Problem& problem) = 0;

 protected:
  // Whether the interrupt has fired (the pass under way is incomplete).
  bool Interrupted() const { return interrupt_ != nullptr && interrupt_->fired(); }

  Interrupt* interrupt_ = nullptr;
};

// The active-set bookkeeping shared by the algorithms that decide every scalar with an
// exact proximal rule (IBFFD, IFFBDD): the region of each decided scalar in the last pass,
// and the regions the polish works with.
class ActiveSetIteration : public OuterIteration {
 public:
  void AdoptRegionsForPolish() override { polish_region_ = region_; }
  void AcceptPolishRegions() override { region_ = polish_region_; }
  bool has_regions() const override { return has_regions_; }
  int decided_scalars() const override { return static_cast<int>(region_.size()); }

 protected:
  // Snapshots: the regions carried from the last solve (the polish ones are per pass).
  void PersistRegions(StateArchive& archive);

  std::vector<Region> region_, polish_region_;  ///< one per decided scalar
  bool has_regions_ = false;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_OUTER_ITERATION_H_
