#include "core/session/infeasibility.h"

namespace nupmpc::core {

void InfeasibilityWatch::Start() {
  passes_ = -1;  // the next observed pass opens the first window
  explosive_windows_ = 0;
  stalled_windows_ = 0;
}

void InfeasibilityWatch::OpenWindow(double largest_dual, double max_violation) {
  passes_ = 0;
  window_dual_ = largest_dual;
  window_violation_ = max_violation;
  window_kept_violation_ = true;
  window_settled_ = true;
}

bool InfeasibilityWatch::Observe(double largest_dual, double max_violation, bool objective_settled,
                                 double violation_tolerance) {
  // Without multipliers (not a dual method) or within the tolerance there is nothing to
  // certify: the windows start again.
  if (!(largest_dual > 0.0) || max_violation <= violation_tolerance) {
    Start();
    return false;
  }
  if (passes_ < 0) {
    OpenWindow(largest_dual, max_violation);
    return false;
  }
  ++passes_;
  window_kept_violation_ = window_kept_violation_ && max_violation >= window_violation_;
  window_settled_ = window_settled_ && objective_settled;
  if (passes_ < kWindow) return false;
  // The window is complete: this pass ends it and opens the next one.
  const bool kept = max_violation >= kViolationKept * window_violation_;
  explosive_windows_ = kept && largest_dual >= kGrowth * window_dual_ ? explosive_windows_ + 1 : 0;
  stalled_windows_ =
      window_kept_violation_ && window_settled_ && largest_dual > window_dual_ ? stalled_windows_ + 1 : 0;
  OpenWindow(largest_dual, max_violation);
  return explosive_windows_ >= kExplosiveWindows || stalled_windows_ >= kStalledWindows;
}

}  // namespace nupmpc::core
