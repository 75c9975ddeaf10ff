#ifndef NUPMPC_CORE_PUBLIC_STANDALONE_STEP_CONTROL_H_
#define NUPMPC_CORE_PUBLIC_STANDALONE_STEP_CONTROL_H_

// Levenberg-Marquardt step control of sequential linearisation with proximal terms: when a
// linearised problem's plan is kept, and how wide the proximal terms are for the next one.
// One copy of the rules for both places that linearise: the core's SequentialSolver
// (core/nonlinear/sequential_solver.h) and the client's NonlinearSession
// (client/nonlinear_session.h). The C++ standard library only, so that the client, which
// has no linear algebra and does not link the core, can include it.
//
// The proximal terms' standard deviations are multiplied by a scale that starts at 1 for
// each sequence: after a linearised problem solved to convergence the scale grows by
// `growth` (up to `max_scale`), so steps lengthen while the linear models keep predicting
// well; a plan the rules reject is discarded and the same point re-linearised with the
// scale divided by `shrink`. shrink = 1 turns the control off.

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <optional>
#include <utility>

namespace nupmpc {

// What the rules judge a linearised problem's plan by.
struct StepTrial {
  // The solve stopped at the iteration cap of this linearisation. A solve stopped because
  // the caller's budget for the whole sequence ran out says nothing about the
  // linearisation (its plan is then judged by its model error alone).
  bool hit_own_cap = false;
  double violation = 0.0;  // how far the plan is from the nonlinear model (defect, violation)
  double step = 0.0;       // max-norm change of states and inputs from the point to the plan
};

// A field the rules cannot work with, for the caller's error message in its own terms.
struct StepControlError {
  const char* field;
  double value;
  const char* requirement;  // e.g. "must be finite and ≥ 1"
};

struct StepControl {
  double growth = 1.0;
  double max_scale = 1.0;
  double shrink = 1.0;
  // A plan whose violation exceeds both the floor and `model_error` times its step is
  // discarded, unless it halved the last accepted plan's violation (a point that is itself
  // far from the model must be repaired by a step no proximal width shortens).
  double model_error = 0.1;
  double violation_floor = 1e-6;

  bool active() const { return shrink > 1.0; }

  // The first field out of range (growth, max_scale, shrink: finite and ≥ 1; model_error:
  // finite and > 0; violation_floor: finite and ≥ 0), or none.
  std::optional<StepControlError> FirstInvalid() const {
    for (const auto& [field, value] : {std::pair{"growth", growth}, {"max_scale", max_scale}, {"shrink", shrink}}) {
      if (!(value >= 1.0) || !std::isfinite(value)) return StepControlError{field, value, "must be finite and ≥ 1"};
    }
    if (!(model_error > 0.0) || !std::isfinite(model_error)) {
      return StepControlError{"model_error", model_error, "must be finite and > 0"};
    }
    if (!(violation_floor >= 0.0) || !std::isfinite(violation_floor)) {
      return StepControlError{"violation_floor", violation_floor, "must be finite and ≥ 0"};
    }
    return std::nullopt;
  }

  // Whether the plan of `trial` is discarded, given the violation of the last plan these
  // rules accepted in this sequence (+∞ before the first: the first plan is kept unless its
  // solve hit its cap). A solve that hit its own cap was typically linearised with too wide
  // a proximal term (it promised too much, or is infeasible).
  bool Rejects(const StepTrial& trial, double accepted_violation) const {
    if (!active()) return false;
    if (trial.hit_own_cap) return true;
    if (trial.violation <= 0.5 * accepted_violation) return false;
    return trial.violation > std::max(violation_floor, model_error * trial.step);
  }

  // The scale after a kept plan whose solve converged, and after a discarded plan.
  double Grown(double scale) const { return scale < max_scale ? std::min(scale * growth, max_scale) : scale; }
  double Shrunk(double scale) const { return scale / shrink; }

  // What the step tolerance is multiplied by at `scale`: while the terms are narrower than
  // their widest, steps are short because they are damped; the terms' pull, step/(scale·σ)²,
  // is what must vanish, so the tolerance shrinks with the square of the scale.
  double ToleranceFactor(double scale) const {
    const double narrowed = std::min(1.0, scale / max_scale);
    return narrowed * narrowed;
  }
};

}  // namespace nupmpc

#endif  // NUPMPC_CORE_PUBLIC_STANDALONE_STEP_CONTROL_H_
