#ifndef NUPMPC_CORE_ALGORITHMS_IFFBDD_INTERIOR_POINT_H_
#define NUPMPC_CORE_ALGORITHMS_IFFBDD_INTERIOR_POINT_H_

#include <vector>

#include "Eigen/Core"
#include "core/algorithms/interior_point_rows.h"
#include "core/algorithms/primal_iterate.h"
#include "core/model/factor_graph.h"
#include "core/options.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

// IFFBDD's primal-dual interior-point iteration (Iffbdd's class comment): Mehrotra's
// predictor-corrector with Gondzio's centrality correctors, each direction a Newton pass of
// IFFBDD's forward filter and backward sweep with the interior-point rows' factors
// (InteriorPointRows). Used for problems whose only constrained rows are hard output
// bounds; its iterates feed the same active-set polish as IFFBDD's own.
//
// Sized once (Acquire); no method allocates.
class IffbddInteriorPoint {
 public:
  // The passes it runs on IFFBDD's graph (Iffbdd implements them).
  class Passes {
   public:
    virtual ~Passes() = default;
    virtual const FactorGraph& graph() const = 0;
    // One factor per row, what the next filter pass sees.
    virtual ScalarFactor* row_factors() = 0;
    // The first pass of a solve: a filter pass that starts each row of `rows` when it
    // reaches it (from its prediction and prior variance), then a Newton pass. False when
    // the filter was interrupted.
    virtual bool StartingPass(InteriorPointRows* rows, PrimalIterate* out) = 0;
    // A filter pass with row_factors() (`full_filter`: gains too, else the means with the
    // last pass's gains), then a Newton pass: the rows' values into newton_values(), the
    // plan into `out`. False when interrupted.
    virtual bool NewtonPass(bool full_filter, PrimalIterate* out) = 0;
    virtual const Eigen::VectorXd& newton_values() const = 0;
    // The last filter pass's prediction variance of row r.
    virtual double PredictedVariance(int r) const = 0;
    virtual bool PassInterrupted() const = 0;
  };

  // What Iterate returns instead of a count of region changes.
  static constexpr int kInterrupted = -1;  // incomplete: discarded by the driver
  static constexpr int kBreakdown = -2;    // this solve goes on with IFFBDD's own iteration

  explicit IffbddInteriorPoint(const SolverOptions& options);

  // Whether the options and the graph's shape admit it.
  bool MayUse(const FactorGraph& graph) const;
  // Whether the rows' priors admit it now; the next solve starts afresh.
  void Decide(const FactorGraph& graph);
  // Whether the passes of this solve are its iterations (else IFFBDD's).
  bool iterates() const { return active_ && !dual_iteration_; }
  // A new solve begins (new values or a shifted horizon): the iteration starts afresh. A
  // solve that adopts carried regions (warm) iterates with IFFBDD's own carried dual state
  // instead (UseDualIteration), which a solve near the last one's optimum needs few passes
  // of (an interior point always starts from the middle); so does one whose interior point
  // broke down.
  void ForgetSolve() {
    started_ = false;
    dual_iteration_ = false;
  }
  void UseDualIteration() { dual_iteration_ = true; }

  void Release();
  void Acquire(const FactorGraph& graph);

  // One iteration (a filter pass for the predictor, means-only passes with the same gains
  // for the corrector): the plan into `out`, the regions the polish would start from into
  // `region`. Returns the region changes, kInterrupted or kBreakdown.
  int Iterate(Passes& passes, std::vector<Region>* region, PrimalIterate* out);
  double largest_multiplier() const { return rows_.largest_multiplier(); }

 private:
  // A Newton pass with the factors of the rows' last Aim: the rows' new values, their
  // directions, and the plan into `out`. False when interrupted.
  bool SolveNewtonDirection(Passes& passes, bool full_filter, PrimalIterate* out);

  const bool enabled_;  ///< by the options
  const double objective_tolerance_;
  bool active_ = false;          ///< the problem gets it now (Decide)
  bool started_ = false;         ///< it has started in this solve
  bool dual_iteration_ = false;  ///< this solve iterates with IFFBDD's updates (ForgetSolve)
  InteriorPointRows rows_;
  PrimalIterate plan_;         ///< its plan, moved by the primal steps
  PrimalIterate newton_plan_;  ///< the direction's plan before a centrality correction
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_IFFBDD_INTERIOR_POINT_H_
