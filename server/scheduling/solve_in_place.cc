#include "server/scheduling/solve_in_place.h"

namespace nupmpc::server {

bool IsShortSolve(const InPlaceInputs& in) {
  return in.inline_max_ms > 0.0 && in.expected_cpu_ms >= 0.0 && in.expected_cpu_ms <= in.inline_max_ms;
}

bool SolvesInPlace(const InPlaceInputs& in) {
  if (in.inline_max_ms <= 0.0 || in.expected_cpu_ms < 0.0) return false;
  if (IsShortSolve(in)) return true;
  if (!in.left_ms.has_value() || in.expected_cpu_ms > kDeadlineInPlaceFactor * in.inline_max_ms) return false;
  const double left_ms = *in.left_ms;
  return in.expected_cpu_ms <= left_ms && in.expected_cpu_ms + in.handoff_ms > left_ms;
}

}  // namespace nupmpc::server
