#include "core/session/elastic.h"

namespace nupmpc::core {

void FindHardOutputBounds(const Problem& problem, HardBounds* bounds) {
  bounds->clear();
  for (std::size_t i = 0; i < problem.output_priors.size(); ++i) {
    const ScalarPrior& prior = problem.output_priors[i];
    if (prior.is_constraint() && prior.is_hard()) bounds->push_back(static_cast<int>(i));
  }
}

void SetBoundSlopes(const HardBounds& bounds, double slope, Problem* problem) {
  for (const int i : bounds) problem->output_priors[i].slope = slope;
}

void ElasticFallback::Continue(Solve* solve, Interrupt* interrupt, const SolveLimits& limits, int max_iterations,
                               double violation_tolerance, SolveSummary* summary) const {
  SolveLimits rest = limits;  // the time limit and cancel flag act through the interrupt
  rest.max_iterations = max_iterations - summary->iterations;
  if (StopNow(interrupt, summary)) return;
  // The same algorithm on the elastic form (ElasticFormApplies checked it), from a cold
  // start: the hard problem's dual iterate may exceed the slope.
  SetBoundSlopes(hard_bounds_, slope_, solve->mutable_problem());
  solve->OutputPriorsChanged();
  solve->ColdStart();
  const SolveSummary elastic = solve->RunLoop(rest, /*warm=*/false);
  // The best iterate is the elastic plan, or the hard loop's (a plan of this solve too).
  summary->has_plan = summary->has_plan || elastic.has_plan;
  SetBoundSlopes(hard_bounds_, kInfinity, solve->mutable_problem());
  solve->OutputPriorsChanged();
  // The elastic plan (or, if the elastic loop broke down, the hard one): judged against
  // the hard bounds.
  const ObjectiveEvaluator::Result r = solve->EvaluatePlan();
  summary->iterations += elastic.iterations;
  summary->objective = r.objective;
  summary->max_violation = r.max_violation;
  summary->polished = elastic.polished;
  summary->elastic = true;
  summary->status = elastic.status;
  if (elastic.status == SolveStatus::kConverged && r.max_violation > violation_tolerance) {
    summary->status = SolveStatus::kInfeasible;
  }
}

}  // namespace nupmpc::core
