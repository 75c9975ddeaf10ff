#ifndef NUPMPC_CORE_SESSION_ELASTIC_H_
#define NUPMPC_CORE_SESSION_ELASTIC_H_

// The elastic fallback of a session (SolverOptions.elastic_slope): a problem whose hard
// output bounds cannot all be met (a measured state outside what the inputs can correct,
// contradictory bounds) has no solution, and a dual method such as IFFBDD then runs to its
// iteration limit. Its elastic form replaces every hard output box and half-space by the
// exact penalty slope·(distance outside the bound), which always has a minimiser; one that
// meets every bound solves the hard problem too (it minimises J over a larger set), and
// one that does not is the least-penalty plan a controller can still apply. Input bounds
// stay hard: they are the actuator's limits, and the plan must be one it can apply.

#include <vector>

#include "core/options.h"
#include "core/priors/scalar_prior.h"
#include "core/problem.h"

namespace nupmpc::core {

// The hard output bounds of a problem: indices into Problem::output_priors.
using HardBounds = std::vector<int>;

// Fills `bounds` (reusing its storage: no allocation once it has grown to size).
void FindHardOutputBounds(const Problem& problem, HardBounds* bounds);

// Gives every bound in `bounds` the slope `slope` (+∞ makes them hard again).
void SetBoundSlopes(const HardBounds& bounds, double slope, Problem* problem);

// Whether the session's algorithm also solves the elastic form: IFFBDD, the algorithm of
// output constraints, whose conditions (prior kinds, Gaussian parts on the inputs) the
// elastic form keeps. IAKE turns hard bounds into finite slopes itself; IBFFD has no
// output bounds.
inline bool ElasticFormApplies(const HardBounds& bounds, Algorithm algorithm) {
  return !bounds.empty() && algorithm == Algorithm::kIffbdd;
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_ELASTIC_H_
