#ifndef NUPMPC_CORE_SESSION_INFEASIBILITY_H_
#define NUPMPC_CORE_SESSION_INFEASIBILITY_H_

// Detects an empty constraint set from a dual method's passes (IFFBDD, nup-algorithms.md
// §9). The dual of a problem with no feasible point is unbounded: the multipliers ỹ grow
// without bound along a direction d that leaves the primal iterate unchanged (Gᵀd = 0,
// since the inputs are recovered as μ - σ²·Bᵀx̃) and along which the dual objective rises
// (the violation stays positive). A feasible problem's multipliers converge to finite
// ones and its violation goes to zero. Two regimes show the first case:
//
//  * explosive: the largest |ỹ| grows by at least kGrowth per window of kWindow passes,
//    for kExplosiveWindows windows in a row, while the violation at each window's end
//    keeps at least kViolationKept of its value at the window's start (a bound out of
//    reach: the dual NUP precisions 2|ỹ|/γ diverge geometrically, and the iterate with
//    them);
//  * stalled: the primal iterate has stopped moving (the objective test of the solve loop
//    holds at every pass) while the violation never falls below its value at the
//    window's start and the largest |ỹ| keeps growing, for kStalledWindows windows in a
//    row (a barely missed bound: the dual creeps along d, the primal does not move).
//
// O(1) per pass, no allocation. Only passes of the plain iteration are observed (the
// polish passes solve another, fixed-region problem).
namespace nupmpc::core {

class InfeasibilityWatch {
 public:
  static constexpr int kWindow = 3;
  static constexpr double kGrowth = 2.0;
  static constexpr double kViolationKept = 0.9;
  static constexpr int kExplosiveWindows = 4;
  static constexpr int kStalledWindows = 7;

  // A new iteration loop (the multipliers start again from the cold or carried ones).
  void Start();
  // After a complete, finite pass: the algorithm's largest |multiplier|
  // (OuterIteration::largest_dual(), 0 when it has none), the iterate's max violation,
  // whether the solve loop's objective test held, and the loop's violation tolerance.
  // True once the passes show an empty constraint set.
  bool Observe(double largest_dual, double max_violation, bool objective_settled, double violation_tolerance);

 private:
  void OpenWindow(double largest_dual, double max_violation);

  int passes_ = -1;  ///< completed since the current window opened (-1: none open)
  double window_dual_ = 0.0, window_violation_ = 0.0;
  bool window_kept_violation_ = true;  ///< no pass of the window fell below window_violation_
  bool window_settled_ = true;         ///< the objective test held at every pass of the window
  int explosive_windows_ = 0, stalled_windows_ = 0;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_INFEASIBILITY_H_
