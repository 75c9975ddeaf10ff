#include "core/algorithms/objective.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/message_passing/fixed_size.h"
#include "core/priors/scalar_rules.h"

namespace nupmpc::core {

void ObjectiveEvaluator::Prepare(const Problem& p) {
  x_.setZero(p.num_states, p.horizon + 1);
  y_.setZero(p.num_outputs, p.horizon + 1);
  dx_.setZero(p.num_states);
  tmp_.setZero(p.num_states);
  x0_free_ = !p.initial_state_fixed();
  if (x0_free_) v0_llt_.compute(p.initial_covariance);
  double scale = 0.0;
  const auto visit = [&scale](const ScalarPrior& prior) {
    if (!prior.is_discrete() && (!prior.is_constraint() || !prior.is_hard())) return;
    if (prior.kind != PriorKind::kAtMost) scale = std::max(scale, std::abs(prior.lower));
    if (prior.kind != PriorKind::kAtLeast) scale = std::max(scale, std::abs(prior.upper));
  };
  std::for_each(p.input_priors.begin(), p.input_priors.end(), visit);
  std::for_each(p.output_priors.begin(), p.output_priors.end(), visit);
  bound_scale_ = scale > 0.0 ? scale : 1.0;
}

// x[n+1] = A x[n] + B u[n] + c[n] and y[n] = C x[n] (offsets d are added by the caller).
// Evaluate() runs once per iteration: with dynamic sizes these small products cost as
// much as the message passing itself (corridor, M = 3), hence the fixed-size kernels.
template <int MS>
bool ObjectiveEvaluator::Simulate(const Problem& p, const PrimalIterate& it, Interrupt* interrupt) {
  const int M = p.num_states, N = p.horizon, L = p.num_inputs, K = p.num_outputs;
  const auto state = [&](int n) { return Eigen::Map<StateVector<MS>>(x_.col(n).data(), M); };
  state(0) = it.x0.head(M);
  StopPoll stop(interrupt, interrupt != nullptr ? interrupt->IntervalFor(2.0 * M * (M + L + K)) : 1);
  for (int n = 0;; ++n) {
    if (stop()) return false;
    if (K > 0) y_.col(n).noalias() = ConstView<Eigen::Dynamic, MS>(p.C_at(n).data(), K, M) * state(n);
    if (n == N) break;
    auto next = state(n + 1);
    StateProduct<MS>(next, ConstView<MS, MS>(p.A_at(n).data(), M, M), state(n));
    next.noalias() += ConstView<MS, Eigen::Dynamic>(p.B_at(n).data(), M, L) * it.u.col(n);
    if (!p.state_offset.empty()) next += p.state_offset.size() == 1 ? p.state_offset[0] : p.state_offset[n];
  }
  return true;
}

ObjectiveEvaluator::Result ObjectiveEvaluator::Evaluate(const Problem& p, const PrimalIterate& it,
                                                        Interrupt* interrupt) {
  Result r;
  const int N = p.horizon, L = p.num_inputs, K = p.num_outputs;
  if (!DispatchStateSize(p.num_states, [&]<int MS>() { return Simulate<MS>(p, it, interrupt); })) {
    return Result{std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  }
  if (x0_free_) {
    dx_ = x_.col(0) - p.initial_mean;
    tmp_ = dx_;
    v0_llt_.solveInPlace(tmp_);
    r.objective += 0.5 * dx_.dot(tmp_);
  }
  for (int n = 0; n <= N; ++n) {
    for (int k = 0; k < K; ++k) {
      const double y = y_(k, n) + p.output_offset_at(n, k);
      y_(k, n) = y;
      const ScalarPrior& prior = p.output_prior(n, k);
      r.objective += PriorCost(prior, y);
      r.max_violation = std::max(r.max_violation, HardViolation(prior, y));
    }
    if (n < N) {
      for (int l = 0; l < L; ++l) {
        const double u = it.u(l, n);
        const ScalarPrior& prior = p.input_prior(n, l);
        r.objective += PriorCost(prior, u);
        r.max_violation = std::max(r.max_violation, HardViolation(prior, u));
      }
    }
  }
  if (p.terminal.has_value()) {
    dx_ = x_.col(N) - p.terminal->target;
    tmp_.noalias() = p.terminal->weight * dx_;
    r.objective += 0.5 * dx_.dot(tmp_);
  }
  return r;
}

}  // namespace nupmpc::core
