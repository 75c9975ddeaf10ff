#ifndef NUPMPC_CORE_NONLINEAR_NONLINEAR_MODEL_H_
#define NUPMPC_CORE_NONLINEAR_NONLINEAR_MODEL_H_

// A user's nonlinear discrete-time plant for sequential linearisation ([KL] §V-E,
// eqs. 111–115; nup-algorithms.md §6.4):
//
//   x[n+1] = f(n, x[n], u[n]),   y[n] = h(n, x[n])
//
// Each linearisation around the previous plan (x*, u*) gives the LTV model the NUP core
// solves: A[n] = ∂f/∂x, B[n] = ∂f/∂u, c[n] = f(x*, u*) - A x* - B u*,
// C[n] = ∂h/∂x, d[n] = h(x*) - C x*. The priors, x[0] and the terminal cost are the
// caller's, on the nonlinear problem's inputs and outputs.

#include <functional>
#include <memory>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nonlinear/sequential_solver.h"
#include "core/problem.h"

namespace nupmpc::core {

struct NonlinearModel {
  int num_states = 0;
  int num_inputs = 0;
  int num_outputs = 0;
  // Writes f(n, x, u) and its Jacobians (sized M, M×M, M×L by the caller).
  std::function<void(int n, const Eigen::VectorXd& x, const Eigen::VectorXd& u, Eigen::VectorXd* next,
                     Eigen::MatrixXd* dfdx, Eigen::MatrixXd* dfdu)>
      transition;
  // Writes h(n, x) and its Jacobian (sized K, K×M).
  std::function<void(int n, const Eigen::VectorXd& x, Eigen::VectorXd* y, Eigen::MatrixXd* dhdx)> output;
};

// A trust region per state component: each linearised problem keeps x_i[n] within
// radius_i of the linearisation point (a hard box on an extra output, appended after the
// model's outputs). Linear models of some plants reward leaving their region of validity
// without bound (a minimal-time problem's dt/ds = 1/v linearised says "drive infinitely
// fast"); the trust region stops that. A converged plan whose step ended strictly inside
// every radius is a stationary point of the nonlinear problem, not of the boxed one.
//
// A proximal term is the soft form: a Gaussian prior N(x*_i[n], σ_i²) on x_i[n] around the
// linearisation point (a Levenberg-Marquardt damping of the sequential method). It makes
// each linearised problem strictly convex in those states and shortens steps where the
// linear model promises much, and it vanishes at a fixed point (x = x*), so a converged
// plan is a stationary point of the undamped nonlinear problem.
struct TrustRegion {
  Eigen::VectorXd state_radius;           ///< size M, > 0; +∞ = no bound on that state; empty = none
  Eigen::VectorXd state_proximal_stddev;  ///< size M, > 0; +∞ = no term on that state; empty = none
  // The same on the inputs, multiplied into the Gaussian part of their priors (the product
  // of N(m, V) and N(u*, σ²) is a Gaussian).
  Eigen::VectorXd input_proximal_stddev;  ///< size L, > 0; +∞ = no term on that input; empty = none
};

// `problem` gives the horizon, priors, x[0] and terminal cost; its model fields are
// ignored (the linearisation writes one matrix per step). Its dimensions must match the
// model's: INVALID_ARGUMENT naming the field otherwise.
absl::StatusOr<std::unique_ptr<Linearisation>> MakeModelLinearisation(NonlinearModel model, const Problem& problem,
                                                                      TrustRegion trust_region = {});

// Simulates the model from x[0] under `inputs` (N × L): states (N+1) × M.
Eigen::MatrixXd SimulateNonlinear(const NonlinearModel& model, const Eigen::VectorXd& x0,
                                  const Eigen::MatrixXd& inputs);

// Largest difference between the model's Jacobians and central finite differences at
// (n, x, u), relative to 1 + the Jacobian's size: a check for hand-written derivatives.
double JacobianError(const NonlinearModel& model, int n, const Eigen::VectorXd& x, const Eigen::VectorXd& u);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_NONLINEAR_NONLINEAR_MODEL_H_
