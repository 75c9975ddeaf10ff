#include "core/algorithms/iffbdd_input_polish.h"

#include <algorithm>
#include <utility>

namespace nupmpc::core {

IffbddInputPolish::IffbddInputPolish(const Problem& problem, const FactorGraph& graph, bool inputs_constrained,
                                     const SolverOptions& options)
    // Without input constraints the sub-problem would be unconstrained: nothing to predict,
    // and active outputs (random_outbox) would waste its attempts.
    : used_(inputs_constrained &&
            std::all_of(problem.output_priors.begin(), problem.output_priors.end(),
                        [](const ScalarPrior& p) { return p.kind != PriorKind::kL1; }) &&
            options.polish_after_stable_iterations > 0) {
  if (!used_) return;
  policy_ = std::make_unique<IbffdPolicy>(problem, /*check_outputs=*/true);
  region_.resize(static_cast<std::size_t>(graph.N) * graph.L);
  input_row_.assign(static_cast<std::size_t>(graph.N) * graph.L, -1);
  for (int r = 0; r < graph.num_rows(); ++r) {
    const RowOrigin& o = graph.row_origin[r];
    if (o.type == RowOrigin::Type::kInput) input_row_[o.step * graph.L + o.index] = r;
  }
}

void IffbddInputPolish::ColdStart() {
  if (policy_) policy_->Forget();
  released_.valid = false;
}

void IffbddInputPolish::Shift() {
  if (policy_) policy_->Shift();
  if (released_.valid) ++released_.shifts;
}

void IffbddInputPolish::Release() {
  if (!policy_) return;
  released_ = policy_->TakeMemory();
  policy_.reset();
}

void IffbddInputPolish::Acquire(const Problem& problem, Interrupt* interrupt) {
  if (!used_ || policy_) return;
  policy_ = std::make_unique<IbffdPolicy>(problem, /*check_outputs=*/true);
  policy_->set_interrupt(interrupt);
  policy_->RestoreMemory(std::move(released_));
  released_ = {};
}

void IffbddInputPolish::Start(const std::vector<Region>& region, bool carried) {
  for (std::size_t i = 0; i < input_row_.size(); ++i) region_[i] = region[input_row_[i]];
  policy_->StartPolish(carried);
}

void IffbddInputPolish::ProposedRegions(std::vector<Region>* region) const {
  std::fill(region->begin(), region->end(), Region::kInside);
  for (std::size_t i = 0; i < input_row_.size(); ++i) (*region)[input_row_[i]] = region_[i];
}

}  // namespace nupmpc::core
