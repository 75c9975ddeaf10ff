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

}  // namespace nupmpc::core
