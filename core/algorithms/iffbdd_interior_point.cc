#include "core/algorithms/iffbdd_interior_point.h"

#include <algorithm>
#include <cmath>

namespace nupmpc::core {

IffbddInteriorPoint::IffbddInteriorPoint(const SolverOptions& options)
    : enabled_(options.interior_point && options.polish_after_stable_iterations > 0),
      objective_tolerance_(options.objective_tolerance) {}

bool IffbddInteriorPoint::MayUse(const FactorGraph& graph) const { return enabled_ && !graph.augmented; }

void IffbddInteriorPoint::Decide(const FactorGraph& graph) {
  const auto& rows = graph.row_prior;
  active_ = MayUse(graph) && std::all_of(rows.begin(), rows.end(), InteriorPointHandles) &&
            std::any_of(rows.begin(), rows.end(), [](const ScalarPrior& p) { return p.is_constraint(); });
  ForgetSolve();
}

void IffbddInteriorPoint::Release() {
  rows_ = InteriorPointRows();
  plan_ = newton_plan_ = PrimalIterate();
  ForgetSolve();
}

void IffbddInteriorPoint::Acquire(const FactorGraph& graph) {
  // Its state, when the problem's shape admits it (its priors may still change: Decide
  // decides at each refresh).
  if (!MayUse(graph)) return;
  rows_.Resize(graph.num_rows());
  plan_.Resize(graph.base_M, graph.L, graph.N);
  newton_plan_.Resize(graph.base_M, graph.L, graph.N);
}

int IffbddInteriorPoint::Iterate(Passes& passes, std::vector<Region>* region, PrimalIterate* out) {
  const FactorGraph& g = passes.graph();
  const int R = g.num_rows();
  ScalarFactor* const row_factor = passes.row_factors();
  // Predictor (affine-scaling direction, target 0). The first pass of a solve starts each
  // row when the filter reaches it, knowing the row's prediction and prior variance.
  if (!started_) {
    rows_.Forget();
    if (!passes.StartingPass(&rows_, out)) return kInterrupted;
    plan_.u.setZero();
    plan_.x0 = g.m0.head(g.base_M);
    started_ = true;
    rows_.TakeDirections(passes.newton_values());
  } else {
    rows_.AimPredictor(row_factor);
    if (!SolveNewtonDirection(passes, /*full_filter=*/true, out)) return kInterrupted;
  }
  if (passes.PassInterrupted()) return kInterrupted;
  // The regions the polish would start from: where the predictor's full step would put
  // each row (its limit as μ → 0, a better guess of the optimum's active set than the
  // current iterate's, whose rows near their bounds still sit at a distance set by μ).
  int changed = 0;
  for (int r = 0; r < R; ++r) {
    const Region next = rows_.active(r) ? rows_.RegionOf(r, passes.PredictedVariance(r), 1.0) : Region::kInside;
    if (next != (*region)[r]) ++changed;
    (*region)[r] = next;
  }
  // Mehrotra's centring σ = (μ_aff / μ)³, from the complementarity the predictor would reach.
  const double mu = rows_.Complementarity();
  const double mu_affine = rows_.Complementarity(std::min(1.0, rows_.MaxStep()));
  const double sigma_mu = mu > 0.0 ? std::min(1.0, std::pow(mu_affine / mu, 3)) * mu : 0.0;
  // Corrector, then Gondzio's centrality correctors while they lengthen the step (his
  // paper's trial step 1.08 α + 0.08 and acceptance at 1.005 α, at most 3); each a means
  // pass with the predictor's gains.
  rows_.AimCorrector(sigma_mu, row_factor);
  if (!SolveNewtonDirection(passes, /*full_filter=*/false, out)) return kInterrupted;
  double reach = rows_.MaxStep();
  for (int correction = 0; correction < 3 && reach < 1.0; ++correction) {
    newton_plan_.u = out->u;
    newton_plan_.x0 = out->x0;
    rows_.AimCentrality(std::min(1.0, 1.08 * reach + 0.08), sigma_mu, row_factor);
    if (!SolveNewtonDirection(passes, /*full_filter=*/false, out)) return kInterrupted;
    const double enhanced = rows_.MaxStep();
    if (enhanced < 1.005 * reach) {
      rows_.Reject();
      out->u = newton_plan_.u;
      out->x0 = newton_plan_.x0;
      break;
    }
    reach = enhanced;
  }
  // A step to a fraction of the boundary (Wright 1997, ch. 10); the plan moves with it.
  const double step = std::isnan(reach) ? reach : std::min(1.0, 0.995 * reach);  // a NaN must reach the test below
  if (!(step > objective_tolerance_) || !out->u.allFinite() || !out->x0.allFinite()) {
    // A breakdown (a slack or multiplier under- or overflowed: NaN), or a step too short
    // to move the objective by the solve loop's tolerance, whose test would then take a
    // stalled iterate for a converged one (an infeasible problem's interior point stalls
    // so): this solve goes on with IFFBDD's own iteration from its carried state, which
    // the interior point never touched, and its infeasibility watch.
    dual_iteration_ = true;
    return kBreakdown;
  }
  rows_.Step(step);
  plan_.u += step * (out->u - plan_.u);
  plan_.x0 += step * (out->x0 - plan_.x0);
  out->u = plan_.u;
  out->x0 = plan_.x0;
  return changed;
}

bool IffbddInteriorPoint::SolveNewtonDirection(Passes& passes, bool full_filter, PrimalIterate* out) {
  if (!passes.NewtonPass(full_filter, out)) return false;
  rows_.TakeDirections(passes.newton_values());
  return true;
}

}  // namespace nupmpc::core
