#ifndef NUPMPC_CORE_SESSION_DISCRETE_SEARCH_H_
#define NUPMPC_CORE_SESSION_DISCRETE_SEARCH_H_

#include "core/algorithms/interrupt.h"
#include "core/algorithms/objective.h"
#include "core/algorithms/primal_iterate.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/solution.h"

namespace nupmpc::core {

// Makes the binary inputs of a solve's plan discrete (nup-algorithms.md §7.2;
// SolverOptions.discrete_*): rounds every binary group (one binary, or an M-level run as
// its sum) to its nearer level, at once or block by block with re-solves of the rest in
// between, then searches the discrete neighbourhood of the rounded plan. It works in place
// on the session's best iterate; the algorithm is reached only through PinnedPasses.
//
// Allocates nothing. One object per solve: it holds pointers into the session.
class DiscreteSearch {
 public:
  // The algorithm's side of the sequential fixing (SolverOptions.discrete_fixing_passes):
  // passes that re-solve the inputs not pinned yet.
  class PinnedPasses {
   public:
    virtual ~PinnedPasses() = default;
    // Pins input scalar `index` (n·L + l) to `value` in the following passes.
    virtual void Pin(int index, double value) = 0;
    virtual void ReleasePins() = 0;
    // One pass with the pins held; writes its plan (pinned inputs exactly as pinned) to
    // `out` and counts it in the summary. False if the solve's limits interrupted it: the
    // pass is incomplete, its plan discarded, and the reason is the summary's status.
    virtual bool Run(SolveSummary* summary, PrimalIterate* out) = 0;
  };

  // `best`: the plan to make discrete; `scratch`: an iterate of the same size for the
  // re-solves. `interrupt` (the solve's) is polled between moves and inside evaluations.
  DiscreteSearch(const Problem& problem, const SolverOptions& options, ObjectiveEvaluator* evaluator,
                 Interrupt* interrupt, PrimalIterate* best, PrimalIterate* scratch)
      : problem_(problem),
        options_(options),
        evaluator_(*evaluator),
        interrupt_(interrupt),
        best_(*best),
        scratch_(*scratch) {}

  // Rounds the plan (with re-solves through `passes` if not null and the options ask for
  // them), searches its neighbours, and reports the discrete plan's objective, violation,
  // gap and moves in the summary (a limit that stops the search in its status).
  void MakeInputsDiscrete(PinnedPasses* passes, SolveSummary* summary);

 private:
  // Rounds the binaries of step n to their nearer levels, pins them through `pins` if not
  // null, and returns the largest distance moved.
  double RoundStep(int n, PinnedPasses* pins);
  // The discrete local search (SolverOptions.discrete_search_sweeps) on the rounded plan;
  // counts its moves in the summary and returns the evaluation of the plan it ends with.
  ObjectiveEvaluator::Result SearchNeighbours(SolveSummary* summary);
  // When the single moves are exhausted: moves two levels of the same binary group at
  // once, each to a neighbouring step, for every pair of steps that carry a level at most
  // SolverOptions.discrete_pair_reach apart (first improvement). On an integrator, one
  // level moved earlier and a later one moved later lifts only the stretch between them:
  // the correction a single move cannot make without shifting everything after it.
  // `try_move` is the search's evaluate-and-keep-or-undo step.
  template <typename TryMove>
  bool TryPairMove(SolveSummary* summary, TryMove& try_move);
  // Moves one level of the group at inputs first..last from step n to step n + direction
  // (±1) if both steps carry that group, n has a level and the other step room for it.
  bool MoveOneLevel(int n, int direction, int first, int last);
  // Binary group (one binary, or an M-level run) starting at input `first` of step n: how
  // many of its binaries are high, and setting that count.
  int GroupLevel(int n, int first, int last) const;
  void SetGroupLevel(int n, int first, int last, int level);
  // The last input of the binary group that starts at input `first` of step n (an M-level
  // run of binaries marked rounds_with_next, or the binary itself).
  int GroupEnd(int n, int first) const;
  // Whether step `other` has the same binary group as step n at inputs first..last.
  bool SameGroupAt(int n, int other, int first, int last) const;

  const Problem& problem_;
  const SolverOptions& options_;
  ObjectiveEvaluator& evaluator_;
  Interrupt* interrupt_;
  PrimalIterate& best_;
  PrimalIterate& scratch_;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_DISCRETE_SEARCH_H_
