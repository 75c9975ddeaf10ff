#ifndef NUPMPC_CORE_ALGORITHMS_IFFBDD_H_
#define NUPMPC_CORE_ALGORITHMS_IFFBDD_H_

#include <vector>

#include "absl/status/status.h"
#include "core/algorithms/iffbdd_input_polish.h"
#include "core/algorithms/iffbdd_interior_point.h"
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
// same passes (SolverOptions.interior_point, IffbddInteriorPoint): IFFBDD's dual updates
// find such an active set at a linear rate (tens of passes on random output boxes),
// Mehrotra's predictor-corrector at a superlinear one. Its iterates feed the same
// active-set polish. A warm solve still starts with the carried active set and, if that
// polish fails, continues with IFFBDD's own iteration.
//
// This class is the dual NUP iteration and its own polish, and runs the passes of both
// collaborators: the interior point (IffbddInteriorPoint) and the polish on the input
// sub-problem (IffbddInputPolish).
class Iffbdd final : public ActiveSetIteration, private IffbddInteriorPoint::Passes {
 public:
  // Why this problem cannot run IFFBDD (OkStatus if it can).
  static absl::Status CheckApplicable(const Problem& problem);
  Iffbdd(const Problem& problem, const SolverOptions& options);

  Algorithm algorithm() const override { return Algorithm::kIffbdd; }
  void set_interrupt(Interrupt* interrupt) override {
    OuterIteration::set_interrupt(interrupt);
    input_polish_.set_interrupt(interrupt);
  }
  void Refresh(const Problem& problem) override;
  void RefreshOutputPriors(const Problem& problem) override;
  void RefreshInitialState(const Problem& problem) override {
    RefreshFactorGraphInitialState(problem, &graph_);
    input_polish_.RefreshInitialState(problem);
    interior_point_.ForgetSolve();
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
  bool NextPolishSolvesInputsOnly() const override { return input_polish_.active() && OutputConstraintsInside(); }
  double largest_dual() const override { return largest_dual_; }
  void ReleaseWorkspace() override;
  void AcquireWorkspace(const Problem& problem) override;
  void PersistState(StateArchive& archive, const Problem& problem) override;

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

  // IffbddInteriorPoint::Passes: the interior point's passes on this graph.
  const FactorGraph& graph() const override { return graph_; }
  ScalarFactor* row_factors() override { return row_factor_.data(); }
  bool StartingPass(InteriorPointRows* rows, PrimalIterate* out) override;
  bool NewtonPass(bool full_filter, PrimalIterate* out) override;
  const Eigen::VectorXd& newton_values() const override { return newton_z_; }
  double PredictedVariance(int r) const override { return fw_.s(r); }
  bool PassInterrupted() const override { return Interrupted(); }

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
  // The warm polish on the input sub-problem, and whether the current polish runs there.
  IffbddInputPolish input_polish_;
  bool polishing_inputs_ = false;
  // The interior-point iteration (see the class comment), and the rows' values of the last
  // Newton pass.
  IffbddInteriorPoint interior_point_;
  Eigen::VectorXd newton_z_;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IFFBDD_H_
