#include "core/session/footprint.h"

#include "core/priors/scalar_prior.h"
#include "core/problem.h"

namespace nupmpc::core {

Footprint EstimateFootprint(const ProblemShape& s) {
  constexpr std::int64_t kDouble = sizeof(double);
  const std::int64_t M = s.num_states, L = s.num_inputs, K = s.num_outputs, N = s.horizon;
  const std::int64_t steps = N + 1;
  Footprint f;
  const std::int64_t model_scalars = (s.a_per_step ? N : 1) * M * M + (s.b_per_step ? N : 1) * M * L +
                                     (s.c_per_step ? steps : 1) * K * M + N * M + steps * K + 2 * M +
                                     (s.uncertain_initial_state ? M * M : 0) + (s.terminal_cost ? M * M : 0);
  f.problem_bytes = model_scalars * kDouble +
                    (N * L + steps * K) * static_cast<std::int64_t>(sizeof(ScalarPrior));
  // Per step: a few M×M message covariances and gains, M×(L+K) gains, and vectors.
  f.workspace_bytes = steps * (6 * M * M + 4 * M * (L + K) + 8 * (M + L + K)) * kDouble;
  // Per scalar NUP state (means, variances, regions) and the primal iterates.
  f.carried_bytes = steps * (8 * (L + K) + 4 * M) * kDouble;
  f.flops_per_step = 12.0 * M * M * M + 8.0 * M * M * (L + K) + 8.0 * M * (L + K) + 32.0 * (L + K);
  f.flops_per_pass = f.flops_per_step * static_cast<double>(steps);
  return f;
}

ProblemShape ShapeOf(const Problem& p) {
  ProblemShape s;
  s.num_states = p.num_states;
  s.num_inputs = p.num_inputs;
  s.num_outputs = p.num_outputs;
  s.horizon = p.horizon;
  s.a_per_step = p.A.size() > 1;
  s.b_per_step = p.B.size() > 1;
  s.c_per_step = p.C.size() > 1;
  s.uncertain_initial_state = !p.initial_state_fixed();
  s.terminal_cost = p.terminal.has_value();
  return s;
}

}  // namespace nupmpc::core
