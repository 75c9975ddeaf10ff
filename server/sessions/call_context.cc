#include "server/sessions/call_context.h"

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {

absl::StatusOr<core::SolveLimits> SolveLimitsFor(double session_limit_ms, const v1::Step* step,
                                                 const CallContext& call) {
  double limit_ms = session_limit_ms;
  if (step != nullptr && step->time_limit_ms() > 0.0) {
    limit_ms = limit_ms > 0.0 ? std::min(limit_ms, step->time_limit_ms()) : step->time_limit_ms();
  }
  if (call.deadline.has_value()) {
    const double left_ms = std::chrono::duration<double, std::milli>(*call.deadline - Clock::now()).count();
    if (left_ms <= 0.0) return absl::DeadlineExceededError("the deadline passed before the solve started");
    limit_ms = limit_ms > 0.0 ? std::min(limit_ms, left_ms) : left_ms;
  }
  core::SolveLimits limits;
  limits.time_limit_seconds = limit_ms > 0.0 ? limit_ms * 1e-3 : 0.0;
  limits.cancel = call.cancel;
  // max_iterations was checked to fit an int by StepUpdateFromProto.
  if (step != nullptr) limits.max_iterations = static_cast<int>(step->max_iterations());
  return limits;
}

absl::StatusOr<gp::FitOptions> FitLimits(const CallContext* call) {
  gp::FitOptions fit;
  if (call == nullptr) return fit;
  fit.cancel = call->cancel;
  if (call->deadline.has_value()) {
    fit.max_seconds = std::chrono::duration<double>(*call->deadline - Clock::now()).count();
    if (fit.max_seconds <= 0.0) return absl::DeadlineExceededError("the deadline passed before the fit started");
  }
  return fit;
}

absl::Status CheckCallStillWanted(const CallContext& call, const char* what) {
  if (call.cancel != nullptr && call.cancel->load()) {
    return absl::CancelledError(absl::StrCat(what, " after the client cancelled the call; it was not kept"));
  }
  if (call.deadline.has_value() && Clock::now() > *call.deadline) {
    return absl::DeadlineExceededError(absl::StrCat(what, " after the call's deadline; it was not kept"));
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::server
