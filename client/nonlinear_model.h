#ifndef NUPMPC_CLIENT_NONLINEAR_MODEL_H_
#define NUPMPC_CLIENT_NONLINEAR_MODEL_H_

// The user's nonlinear plant for NonlinearSession (nonlinear_session.h) and its
// linearisation: Linearise and CheckJacobians, on plain std::vector<double> (row-major).

#include <cstdint>
#include <functional>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace nupmpc {

// The user's plant. `t` is the absolute step of x (and u): the number of periods the
// session has stepped plus the horizon step n, so that plants that change along the way (a
// track's curvature per spatial step, a schedule) know where they are. Time-invariant
// plants ignore it.
struct NonlinearModel {
  using Vector = std::vector<double>;
  int num_states = 0;                                                                  // M ≥ 1
  int num_inputs = 0;                                                                  // L ≥ 1
  int num_outputs = 0;                                                                 // K ≥ 0
  std::function<Vector(std::int64_t t, const Vector& x, const Vector& u)> transition;  // f: M values
  std::function<Vector(std::int64_t t, const Vector& x)> output;  // h: K values (may be empty when K = 0)
  // Optional analytic Jacobians, row-major: ∂f/∂x (M×M), ∂f/∂u (M×L), ∂h/∂x (K×M). Each one
  // left empty is taken by central finite differences. Given ones are checked against
  // finite differences when the session is created (NonlinearSessionOptions.check_jacobians).
  std::function<Vector(std::int64_t t, const Vector& x, const Vector& u)> transition_x;
  std::function<Vector(std::int64_t t, const Vector& x, const Vector& u)> transition_u;
  std::function<Vector(std::int64_t t, const Vector& x)> output_x;
};

// The model linearised at one point (x̄, ū): x⁺ ≈ A x + B u + c, y ≈ C x + d. Row-major.
struct LinearisedStep {
  std::vector<double> A, B, c;  // M×M, M×L, M
  std::vector<double> C, d;     // K×M, K
};

// Where the finite differences are taken: x_j ± h with h = relative_step·(1 + |x_j|).
// Their error is about relative_step² (truncation) plus 1e-16/relative_step (rounding), both
// relative to the size of f and its derivatives: 1e-6 balances the two.
inline constexpr double kDefaultFiniteDifferenceStep = 1e-6;

// The linearisation at (t, x, u), with the user's Jacobians where given and central
// finite differences elsewhere (`force_finite_differences`: everywhere). INVALID_ARGUMENT
// naming the function when one returns the wrong number of values or a non-finite one.
absl::StatusOr<LinearisedStep> Linearise(const NonlinearModel& model, std::int64_t t, const std::vector<double>& x,
                                         const std::vector<double>& u, bool force_finite_differences = false,
                                         double relative_step = kDefaultFiniteDifferenceStep);

// Compares the user's Jacobians (those given) with central finite differences at (t, x, u).
// An entry is wrong when |given − difference| > tolerance·(1 + |difference|): then
// INVALID_ARGUMENT naming the Jacobian, the entry (row, column and what they stand for),
// both values and the point's step, e.g.
//   "NonlinearModel.transition_x (∂f/∂x) at t = 3: entry (2, 3) (∂f_2/∂x_3) is 0.5, central
//    differences give 0.7 (tolerance 1e-05·(1 + |0.7|))".
absl::Status CheckJacobians(const NonlinearModel& model, std::int64_t t, const std::vector<double>& x,
                            const std::vector<double>& u, double tolerance = 1e-5,
                            double relative_step = kDefaultFiniteDifferenceStep);

// For NonlinearSession (nonlinear_session.cc), which linearises along whole plans: the
// pieces Linearise and CheckJacobians are built from. Not meant for other callers.
namespace nonlinear_internal {

// The model's dimensions and required functions; INVALID_ARGUMENT naming the field.
absl::Status ValidateModel(const NonlinearModel& m);

// f(t, x, u) and h(t, x) (empty when K = 0), checked for size and finite values.
absl::StatusOr<std::vector<double>> EvalTransition(const NonlinearModel& m, std::int64_t t,
                                                   const std::vector<double>& x, const std::vector<double>& u);
absl::StatusOr<std::vector<double>> EvalOutput(const NonlinearModel& m, std::int64_t t, const std::vector<double>& x);

// f, h and their Jacobians at one point (x, u).
struct Jacobians {
  std::vector<double> fx, A, B;  // f(x, u), ∂f/∂x, ∂f/∂u
  std::vector<double> hx, C;     // h(x), ∂h/∂x
};
// f and ∂f/∂x, ∂f/∂u at (x, u): the given Jacobians or central differences (hx, C left empty).
absl::StatusOr<Jacobians> TransitionJacobians(const NonlinearModel& m, std::int64_t t, const std::vector<double>& x,
                                              const std::vector<double>& u, bool force_differences,
                                              double relative_step);
// h and ∂h/∂x at x into j->hx and j->C (left as they are when K = 0).
absl::Status OutputJacobian(const NonlinearModel& m, std::int64_t t, const std::vector<double>& x,
                            bool force_differences, double relative_step, Jacobians* j);

// `value` − J·point (the affine term of the linearisation), J rows×cols row-major.
std::vector<double> AffineTerm(const std::vector<double>& value, const std::vector<double>& J,
                               const std::vector<double>& point);

}  // namespace nonlinear_internal
}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_NONLINEAR_MODEL_H_
