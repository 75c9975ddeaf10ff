#include "client/nonlinear_model.h"

#include <cmath>
#include <cstddef>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/status_macros.h"

namespace nupmpc {
namespace {

using Vector = std::vector<double>;

// A user function's answer, refused when it has the wrong size or a non-finite value:
// such a value would otherwise reach the server as a model it refuses with less context.
absl::StatusOr<Vector> Checked(Vector values, std::size_t expected, const char* function, const char* shape,
                               std::int64_t t) {
  if (values.size() != expected) {
    return absl::InvalidArgumentError(absl::StrCat("NonlinearModel.", function, " returned ", values.size(),
                                                   " values at t = ", t, ", expected ", expected, " (", shape, ")"));
  }
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) {
      return absl::InvalidArgumentError(absl::StrCat("NonlinearModel.", function, " returned a non-finite value (",
                                                     values[i], ") at index ", i, " at t = ", t));
    }
  }
  return values;
}

// Central differences of `map` (R^cols → R^rows) at `at`: rows×cols, row-major.
template <typename Map>
absl::StatusOr<Vector> Differences(const Map& map, const Vector& at, int rows, double relative_step) {
  const int cols = static_cast<int>(at.size());
  Vector jacobian(static_cast<std::size_t>(rows) * cols);
  Vector moved = at;
  for (int j = 0; j < cols; ++j) {
    // The step as represented: (x + h) − x, so that the quotient divides by the step taken.
    const double h = (at[j] + relative_step * (1.0 + std::abs(at[j]))) - at[j];
    moved[j] = at[j] + h;
    absl::StatusOr<Vector> plus = map(moved);
    if (!plus.ok()) return plus.status();
    moved[j] = at[j] - h;
    absl::StatusOr<Vector> minus = map(moved);
    if (!minus.ok()) return minus.status();
    moved[j] = at[j];
    for (int i = 0; i < rows; ++i) {
      jacobian[static_cast<std::size_t>(i) * cols + j] = ((*plus)[i] - (*minus)[i]) / (2 * h);
    }
  }
  return jacobian;
}

// One given Jacobian against its finite differences.
absl::Status CompareJacobian(const Vector& given, const Vector& differences, int cols, const char* field,
                             const char* symbol, const char* of, const char* by, std::int64_t t, double tolerance) {
  for (std::size_t e = 0; e < given.size(); ++e) {
    const double error = std::abs(given[e] - differences[e]);
    if (error > tolerance * (1.0 + std::abs(differences[e]))) {
      const std::size_t row = e / cols, col = e % cols;
      return absl::InvalidArgumentError(
          absl::StrCat("NonlinearModel.", field, " (", symbol, ") at t = ", t, ": entry (", row, ", ", col, ") (∂", of,
                       "_", row, "/∂", by, "_", col, ") is ", given[e], ", central differences give ", differences[e],
                       " (tolerance ", tolerance, "·(1 + |", differences[e], "|))"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

namespace nonlinear_internal {

absl::StatusOr<Vector> EvalTransition(const NonlinearModel& m, std::int64_t t, const Vector& x, const Vector& u) {
  return Checked(m.transition(t, x, u), m.num_states, "transition", "M", t);
}

absl::StatusOr<Vector> EvalOutput(const NonlinearModel& m, std::int64_t t, const Vector& x) {
  if (m.num_outputs == 0) return Vector{};
  return Checked(m.output(t, x), m.num_outputs, "output", "K", t);
}

absl::StatusOr<Jacobians> TransitionJacobians(const NonlinearModel& m, std::int64_t t, const Vector& x, const Vector& u,
                                              bool force_differences, double relative_step) {
  const int M = m.num_states, L = m.num_inputs;
  Jacobians j;
  absl::StatusOr<Vector> fx = EvalTransition(m, t, x, u);
  if (!fx.ok()) return fx.status();
  j.fx = *std::move(fx);
  absl::StatusOr<Vector> A =
      m.transition_x && !force_differences
          ? Checked(m.transition_x(t, x, u), M * M, "transition_x", "M×M", t)
          : Differences([&](const Vector& v) { return EvalTransition(m, t, v, u); }, x, M, relative_step);
  if (!A.ok()) return A.status();
  absl::StatusOr<Vector> B =
      m.transition_u && !force_differences
          ? Checked(m.transition_u(t, x, u), M * L, "transition_u", "M×L", t)
          : Differences([&](const Vector& v) { return EvalTransition(m, t, x, v); }, u, M, relative_step);
  if (!B.ok()) return B.status();
  j.A = *std::move(A);
  j.B = *std::move(B);
  return j;
}

absl::Status OutputJacobian(const NonlinearModel& m, std::int64_t t, const Vector& x, bool force_differences,
                            double relative_step, Jacobians* j) {
  const int K = m.num_outputs, M = m.num_states;
  if (K == 0) return absl::OkStatus();
  absl::StatusOr<Vector> hx = EvalOutput(m, t, x);
  if (!hx.ok()) return hx.status();
  absl::StatusOr<Vector> C =
      m.output_x && !force_differences
          ? Checked(m.output_x(t, x), K * M, "output_x", "K×M", t)
          : Differences([&](const Vector& v) { return EvalOutput(m, t, v); }, x, K, relative_step);
  if (!C.ok()) return C.status();
  j->hx = *std::move(hx);
  j->C = *std::move(C);
  return absl::OkStatus();
}

Vector AffineTerm(const Vector& value, const Vector& J, const Vector& point) {
  Vector term = value;
  const std::size_t cols = point.size();
  for (std::size_t i = 0; i < term.size(); ++i) {
    for (std::size_t k = 0; k < cols; ++k) term[i] -= J[i * cols + k] * point[k];
  }
  return term;
}

absl::Status ValidateModel(const NonlinearModel& m) {
  if (m.num_states < 1 || m.num_inputs < 1 || m.num_outputs < 0) {
    return absl::InvalidArgumentError(absl::StrCat("NonlinearModel: num_states (", m.num_states, ") and num_inputs (",
                                                   m.num_inputs, ") must be ≥ 1, num_outputs (", m.num_outputs,
                                                   ") ≥ 0"));
  }
  if (!m.transition) return absl::InvalidArgumentError("NonlinearModel.transition: required");
  if (m.num_outputs > 0 && !m.output) {
    return absl::InvalidArgumentError(
        absl::StrCat("NonlinearModel.output: required when num_outputs = ", m.num_outputs, " > 0"));
  }
  return absl::OkStatus();
}

}  // namespace nonlinear_internal

using nonlinear_internal::AffineTerm;
using nonlinear_internal::Jacobians;
using nonlinear_internal::OutputJacobian;
using nonlinear_internal::TransitionJacobians;
using nonlinear_internal::ValidateModel;

absl::StatusOr<LinearisedStep> Linearise(const NonlinearModel& model, std::int64_t t, const std::vector<double>& x,
                                         const std::vector<double>& u, bool force_finite_differences,
                                         double relative_step) {
  NUPMPC_CLIENT_RETURN_IF_ERROR(ValidateModel(model));
  if (x.size() != static_cast<std::size_t>(model.num_states) ||
      u.size() != static_cast<std::size_t>(model.num_inputs)) {
    return absl::InvalidArgumentError(absl::StrCat("Linearise: x has ", x.size(), " values (expected ",
                                                   model.num_states, "), u ", u.size(), " (expected ", model.num_inputs,
                                                   ")"));
  }
  absl::StatusOr<Jacobians> j = TransitionJacobians(model, t, x, u, force_finite_differences, relative_step);
  if (!j.ok()) return j.status();
  NUPMPC_CLIENT_RETURN_IF_ERROR(OutputJacobian(model, t, x, force_finite_differences, relative_step, &*j));
  LinearisedStep step;
  step.c = AffineTerm(AffineTerm(j->fx, j->A, x), j->B, u);
  step.d = AffineTerm(j->hx, j->C, x);
  step.A = std::move(j->A);
  step.B = std::move(j->B);
  step.C = std::move(j->C);
  return step;
}

absl::Status CheckJacobians(const NonlinearModel& model, std::int64_t t, const std::vector<double>& x,
                            const std::vector<double>& u, double tolerance, double relative_step) {
  NUPMPC_CLIENT_RETURN_IF_ERROR(ValidateModel(model));
  if (!model.transition_x && !model.transition_u && !model.output_x) return absl::OkStatus();
  absl::StatusOr<LinearisedStep> given = Linearise(model, t, x, u, false, relative_step);
  if (!given.ok()) return given.status();
  absl::StatusOr<LinearisedStep> differences = Linearise(model, t, x, u, true, relative_step);
  if (!differences.ok()) return differences.status();
  const int M = model.num_states, L = model.num_inputs;
  if (model.transition_x) {
    NUPMPC_CLIENT_RETURN_IF_ERROR(
        CompareJacobian(given->A, differences->A, M, "transition_x", "∂f/∂x", "f", "x", t, tolerance));
  }
  if (model.transition_u) {
    NUPMPC_CLIENT_RETURN_IF_ERROR(
        CompareJacobian(given->B, differences->B, L, "transition_u", "∂f/∂u", "f", "u", t, tolerance));
  }
  if (model.output_x && model.num_outputs > 0) {
    NUPMPC_CLIENT_RETURN_IF_ERROR(
        CompareJacobian(given->C, differences->C, M, "output_x", "∂h/∂x", "h", "x", t, tolerance));
  }
  return absl::OkStatus();
}

}  // namespace nupmpc
