#ifndef NUPMPC_CORE_ALGORITHMS_IFFBDD_H_
#define NUPMPC_CORE_ALGORITHMS_IFFBDD_H_

#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "core/algorithms/ibffd_policy.h"
#include "core/algorithms/interior_point_rows.h"
#include "core/algorithms/outer_iteration.h"
#include "core/message_passing/forward_filter.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

// IFFBDD ([LL-dual] Alg. 2; nup-algorithms.md §9): forward Kalman filter with dual-NUP
// Gaussians on the constrained rows, backward dual deciding of each row's multiplier ỹ,
// inputs recovered from the costate. Input constraints enter through state augmentation
// (§9.6). Needs a Gaussian part on every input; rows may carry box, half-space (hard or
// soft) and L1 priors.
//
// Problems whose only constrained rows are hard output bounds (no constrained input, no
// soft or L1 row) are iterated instead with a primal-dual interior-point method on the
// same passes (SolverOptions.interior_point, InteriorPointRows): IFFBDD's dual updates find
// such an active set at a linear rate (tens of passes on random output boxes), Mehrotra's
// predictor-corrector at a superlinear one. Its iterates feed the same active-set polish.
// A warm solve still starts with the carried active set and, if that polish fails,
// continues with IFFBDD's own iteration.
class Iffbdd final : public ActiveSetIteration {
 public:
  // Why this problem cannot run IFFBDD (OkStatus if it can).
  static absl::Status CheckApplicable(const Problem& problem);
  Iffbdd(const Problem& problem, const SolverOptions& options);

  Algorithm algorithm() const override { return Algorithm::kIffbdd; }
  void set_interrupt(Interrupt* interrupt) override {
    OuterIteration::set_interrupt(interrupt);
    if (input_polish_) input_polish_->set_interrupt(interrupt);
  }
  void Refresh(const Problem& problem) override;
  void RefreshOutputPriors(const Problem& problem) override;
  void RefreshInitialState(const Problem& problem) override {
    RefreshFactorGraphInitialState(problem, &graph_);
    if (input_polish_) input_polish_->RefreshInitialState(problem);
    ForgetSolve();
  }
  void ColdStart() override;
  void ShiftWarmStart() override;
  int Iterate(PrimalIterate* out) override;
  double Polish(PrimalIterate* out) override;
  void AdoptRegionsForPolish() override;
  // The warm start's first polish pass decides each row's region in the forward filter,
  // knowing the rows before it in this pass and the carried duals of the rows after it
  // (DecideRowForward): when a new x[0] moves the active set, rows that depend on earlier
  // rows' new pins get them in the same pass. Only after a warm start: after cold
  // iterations the duals are the NUP iterate's, and deciding with them costs passes.
  //
  // When every output constraint is inside in the regions a polish starts from (the last
  // solve's for a warm one, the iterate's for a cold one) and some input is constrained,
  // the polish runs on the input sub-problem instead (IbffdPolicy with check_outputs, warm
  // with its carried policy): inactive output constraints change nothing there, and
  // IBFFD's messages predict a moved input active set far better than carried duals do. A
  // pass that finds an output outside its bounds hands the proposed input regions back to
  // this algorithm's own polish.
  void AdoptCarriedRegionsForPolish() override;
  void AcceptPolishRegions() override;
  bool NextPolishSolvesInputsOnly() const override { return input_polish_ && OutputConstraintsInside(); }
  double largest_dual() const override { return largest_dual_; }
  void ReleaseWorkspace() override;
  void AcquireWorkspace(const Problem& problem) override;

 private:
  // kNewton: the exact solution of the pass's Gaussian factors (rows' values into
  // newton_z_), no deciding.
  enum class Pass { kIterate, kPolish, kNewton };
  // The backward dual-deciding pass; returns the region changes (kIterate) or the
  // deciding residual (kPolish).
  double Backward(Pass pass, PrimalIterate* out);
  template <int MS>
  double BackwardImpl(Pass pass, PrimalIterate* out);
  // Whether the polish that starts now runs on the input sub-problem (every output
  // constraint inside in region_); if so, hands it region_'s input regions.
  bool StartInputPolish(bool carried);
  bool OutputConstraintsInside() const;  ///< in region_
  // One interior-point iteration (a filter pass for the predictor, a means-only pass with
  // the same gains for the corrector); returns the region changes like Iterate().
  int IterateInteriorPoint(PrimalIterate* out);
  // A Newton pass with the factors of the interior-point rows' last Aim (a full filter
  // pass, or a means pass with the last one's gains): the rows' new values, their
  // directions, and the plan into `out`. False when interrupted.
  bool SolveNewtonDirection(bool full_filter, PrimalIterate* out);
  // Whether the options and the graph's shape admit the interior-point iteration.
  bool MayUseInteriorPoint() const;
  // A new solve begins (new values or a shifted horizon): the interior-point iteration
  // starts afresh. A solve that adopts carried regions (warm) iterates with IFFBDD's own
  // carried dual state instead, which a solve near the last one's optimum needs few
  // passes of (an interior point always starts from the middle); so does one whose
  // interior point broke down.
  void ForgetSolve() {
    interior_point_started_ = false;
    dual_iteration_ = false;
  }
  // Whether the rows' priors admit it now (sets interior_point_; the next solve starts afresh).
  void DecideInteriorPoint();
  // What Refresh() derives from the graph: the inputs' Gaussian factors (and moments), γ.
  void RefreshDerived();
  // The region (and polish factor) of constrained row r from its forward prediction and the
  // last pass's duals of the rows after it.
  ScalarFactor DecideRowForward(int row, double yhat, double s, const double* v);

  FactorGraph graph_;
  ForwardFilterWorkspace fw_;  ///< scratch, except the input moments loaded by Refresh
  bool workspace_held_ = false;
  std::vector<ScalarFactor> input_factor_;  ///< Gaussian parts of the inputs (fixed)
  std::vector<ScalarFactor> nup_;           ///< dual-NUP factor per row (the carried state)
  std::vector<ScalarFactor> row_factor_;    ///< nup_ × Gaussian part, what the filter sees
  std::vector<double> gamma_;               ///< γ per row (§9.5)
  Eigen::VectorXd costate_, scratch_;
  // The last backward pass's duals, kept for the forward-deciding polish (and shifted with
  // the warm start): the costate entering each step's rows from the later steps, and each
  // row's dual ỹ.
  Eigen::MatrixXd step_costate_;  ///< M × (N+1)
  Eigen::VectorXd row_dual_;      ///< R
  std::vector<int> row_step_;     ///< the step n of each row
  bool has_duals_ = false;
  double largest_dual_ = 0.0;  ///< max |ỹ| over the constrained rows of the last Iterate()
  bool decide_forward_next_ = false;
  // The warm polish on the input sub-problem (used when some input is constrained and every
  // output prior is a box or half-space), its regions of the input scalars (n·L + l), and
  // whether the current polish runs there. It is scratch: ReleaseWorkspace destroys it
  // (most of an idle session's memory) and keeps only its policy's memory;
  // AcquireWorkspace rebuilds it from the problem.
  SolverOptions options_;
  bool uses_input_polish_ = false;
  std::unique_ptr<IbffdPolicy> input_polish_;
  std::vector<Region> input_polish_region_;
  IbffdPolicy::Memory released_policy_;
  bool polishing_inputs_ = false;
  std::vector<int> input_row_;  ///< the augmented row of input scalar n·L + l
  // The interior-point iteration (see the class comment): whether the problem gets it now,
  // whether it has started in this solve, its per-row state, the rows' values of the last
  // Newton pass, and its plan (moved by the primal steps).
  bool interior_point_ = false;
  bool interior_point_started_ = false;
  bool dual_iteration_ = false;  ///< this solve iterates with IFFBDD's updates (ForgetSolve)
  InteriorPointRows interior_rows_;
  Eigen::VectorXd newton_z_;
  PrimalIterate interior_plan_;
  PrimalIterate newton_plan_;  ///< the direction's plan before a centrality correction
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IFFBDD_H_
