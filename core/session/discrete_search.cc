#include "core/session/discrete_search.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/priors/scalar_prior.h"

namespace nupmpc::core {

void DiscreteSearch::MakeInputsDiscrete(PinnedPasses* passes, SolveSummary* summary) {
  const int N = problem_.horizon;
  double gap = 0.0;
  int rounded_steps = 0;
  if (options_.discrete_fixing_passes > 0 && passes != nullptr) {
    const int blocks = std::min(options_.discrete_fixing_blocks, N);
    bool stopped = false;
    for (int block = 0; block < blocks && !stopped; ++block) {
      const int end = static_cast<int>((static_cast<long long>(block) + 1) * N / blocks);
      for (; rounded_steps < end; ++rounded_steps) gap = std::max(gap, RoundStep(rounded_steps, passes));
      if (rounded_steps == N) break;  // nothing left to make up for the rounding
      for (int pass = 0; pass < options_.discrete_fixing_passes; ++pass) {
        if (StopNow(interrupt_, summary) || !passes->Run(summary, &scratch_)) {
          stopped = true;  // an incomplete pass: its plan is discarded
          break;
        }
        if (!AllFinite(scratch_)) break;  // keep the last finite plan; its rounded part stays
        // The pinned inputs come back exactly as pinned; the rest is the re-solved plan.
        std::swap(best_, scratch_);
      }
    }
    passes->ReleasePins();
  }
  for (; rounded_steps < N; ++rounded_steps) gap = std::max(gap, RoundStep(rounded_steps, nullptr));
  const ObjectiveEvaluator::Result r = SearchNeighbours(summary);
  summary->objective = r.objective;
  summary->max_violation = r.max_violation;
  summary->rounded = true;
  summary->discrete_gap = gap;
}

int DiscreteSearch::GroupEnd(int n, int first) const {
  int last = first;
  while (problem_.input_prior(n, last).rounds_with_next) ++last;
  return last;
}

bool DiscreteSearch::SameGroupAt(int n, int other, int first, int last) const {
  const ScalarPrior& here = problem_.input_prior(n, first);
  for (int j = first; j <= last; ++j) {
    const ScalarPrior& next = problem_.input_prior(other, j);
    if (next.kind != PriorKind::kBinary || next.lower != here.lower || next.upper != here.upper ||
        next.rounds_with_next != (j < last)) {
      return false;
    }
  }
  return true;
}

int DiscreteSearch::GroupLevel(int n, int first, int last) const {
  const ScalarPrior& prior = problem_.input_prior(n, first);
  int level = 0;
  for (int j = first; j <= last; ++j) level += best_.u(j, n) == prior.upper;
  return level;
}

void DiscreteSearch::SetGroupLevel(int n, int first, int last, int level) {
  const ScalarPrior& prior = problem_.input_prior(n, first);
  for (int j = first; j <= last; ++j) best_.u(j, n) = j - first < level ? prior.upper : prior.lower;
}

ObjectiveEvaluator::Result DiscreteSearch::SearchNeighbours(SolveSummary* summary) {
  // The rounded plan's own evaluation is not interrupted: it is the one reported.
  ObjectiveEvaluator::Result current = evaluator_.Evaluate(problem_, best_);
  const double tolerance = options_.violation_tolerance * evaluator_.bound_scale();
  // Lower violation first (beyond the tolerance), then lower J.
  const auto better = [tolerance](const ObjectiveEvaluator::Result& trial, const ObjectiveEvaluator::Result& now) {
    if (!std::isfinite(trial.objective) || !std::isfinite(trial.max_violation)) return false;
    if (now.max_violation > tolerance || trial.max_violation > tolerance) {
      return trial.max_violation < now.max_violation - 0.5 * tolerance;
    }
    return trial.objective < now.objective - 1e-12 * (1.0 + std::abs(now.objective));
  };
  // An interrupted evaluation is NaN: never better, so the move is undone (and every
  // later one returns at once until the loops see the stop).
  const auto try_move = [&](auto&& apply, auto&& undo) {
    apply();
    const ObjectiveEvaluator::Result trial = evaluator_.Evaluate(problem_, best_, interrupt_);
    if (better(trial, current)) {
      current = trial;
      ++summary->discrete_moves;
      return true;
    }
    undo();
    return false;
  };
  const int N = problem_.horizon, L = problem_.num_inputs;
  for (int sweep = 0; sweep < options_.discrete_search_sweeps; ++sweep) {
    bool improved = false;
    for (int n = 0; n < N; ++n) {
      if (StopNow(interrupt_, summary)) return current;  // discrete, only less improved
      for (int first = 0; first < L; ++first) {
        if (problem_.input_prior(n, first).kind != PriorKind::kBinary) continue;
        const int last = GroupEnd(n, first);
        const int level = GroupLevel(n, first, last);
        for (const int step : {-1, 1}) {
          const int to = level + step;
          if (to < 0 || to > last - first + 1) continue;
          if (try_move([&] { SetGroupLevel(n, first, last, to); }, [&] { SetGroupLevel(n, first, last, level); })) {
            improved = true;
            break;
          }
        }
        // Move one level between this step and the next one's same group (same binaries):
        // a flap or a switch one step earlier or later, or a +1/-1 doublet, whose effect on
        // an integrator's output stays local.
        if (n + 1 < N && SameGroupAt(n, n + 1, first, last)) {
          const int here = GroupLevel(n, first, last), next = GroupLevel(n + 1, first, last);
          const int top = last - first + 1;
          const auto set_pair = [&](int a, int b) {
            SetGroupLevel(n, first, last, a);
            SetGroupLevel(n + 1, first, last, b);
          };
          for (const int step : {-1, 1}) {
            if (here + step < 0 || here + step > top || next - step < 0 || next - step > top) continue;
            if (try_move([&] { set_pair(here + step, next - step); }, [&] { set_pair(here, next); })) {
              improved = true;
              break;
            }
          }
        }
        first = last;
      }
    }
    if (!improved && options_.discrete_pair_reach > 0) improved = TryPairMove(summary, try_move);
    if (!improved) break;
  }
  return current;  // best_'s evaluation (Solve() re-evaluates it for the returned trajectories)
}

bool DiscreteSearch::MoveOneLevel(int n, int direction, int first, int last) {
  const int to = n + direction;
  if (to < 0 || to >= problem_.horizon || !SameGroupAt(n, to, first, last)) return false;
  const int here = GroupLevel(n, first, last), there = GroupLevel(to, first, last);
  if (here == 0 || there == last - first + 1) return false;
  SetGroupLevel(n, first, last, here - 1);
  SetGroupLevel(to, first, last, there + 1);
  return true;
}

template <typename TryMove>
bool DiscreteSearch::TryPairMove(SolveSummary* summary, TryMove& try_move) {
  const int N = problem_.horizon, L = problem_.num_inputs;
  for (int n1 = 0; n1 < N; ++n1) {
    if (StopNow(interrupt_, summary)) return false;
    for (int first = 0; first < L; ++first) {
      if (problem_.input_prior(n1, first).kind != PriorKind::kBinary) continue;
      const int last = GroupEnd(n1, first);
      if (GroupLevel(n1, first, last) > 0) {
        const int reach = std::min(N - 1, n1 + options_.discrete_pair_reach);
        for (int n2 = n1 + 1; n2 <= reach; ++n2) {
          if (!SameGroupAt(n1, n2, first, last) || GroupLevel(n2, first, last) == 0) continue;
          for (const int d1 : {-1, 1}) {
            for (const int d2 : {-1, 1}) {
              // Undone in reverse order, each move by its exact inverse.
              if (!MoveOneLevel(n1, d1, first, last)) continue;
              if (!MoveOneLevel(n2, d2, first, last)) {
                MoveOneLevel(n1 + d1, -d1, first, last);
                continue;
              }
              const auto undo = [&] {
                MoveOneLevel(n2 + d2, -d2, first, last);
                MoveOneLevel(n1 + d1, -d1, first, last);
              };
              if (try_move([] {}, undo)) return true;
            }
          }
        }
      }
      first = last;
    }
  }
  return false;
}

double DiscreteSearch::RoundStep(int n, PinnedPasses* pins) {
  double gap = 0.0;
  for (int first = 0; first < problem_.num_inputs; ++first) {
    const ScalarPrior& prior = problem_.input_prior(n, first);
    if (prior.kind != PriorKind::kBinary) continue;
    // An M-level group is rounded as its sum: the nearest level.
    const int last = GroupEnd(n, first);
    const double a = prior.lower, b = prior.upper;
    double sum = 0.0;
    for (int j = first; j <= last; ++j) sum += (best_.u(j, n) - a) / (b - a);
    const double high = std::clamp(std::round(sum), 0.0, static_cast<double>(last - first + 1));
    gap = std::max(gap, std::abs(sum - high) * std::abs(b - a));
    SetGroupLevel(n, first, last, static_cast<int>(high));
    for (int j = first; pins != nullptr && j <= last; ++j) pins->Pin(n * problem_.num_inputs + j, best_.u(j, n));
    first = last;
  }
  return gap;
}

}  // namespace nupmpc::core
