#ifndef NUPMPC_TESTS_UTIL_BOUNDED_INTEGRATOR_H_
#define NUPMPC_TESTS_UTIL_BOUNDED_INTEGRATOR_H_

// The smallest problem whose feasibility is known in closed form: x[n+1] = x[n] + u[n] with
// |u| ≤ input_limit (hard) and y = x in [0, 1] (hard) for n ≥ 1, small Gaussian parts. From
// x0 it is feasible iff x0 ≤ 1 + input_limit, and every plan misses the bound at step 1 by at
// least x0 - 1 - input_limit.

#include "Eigen/Core"
#include "core/problem.h"

namespace nupmpc::testing {

inline core::Problem BoundedIntegrator(double x0, int horizon, double input_limit) {
  core::Problem p = core::Problem::TimeInvariant(1, 1, 1, horizon);
  p.A[0] << 1;
  p.B[0] << 1;
  p.C[0] << 1;
  p.initial_mean = Eigen::VectorXd::Constant(1, x0);
  for (core::ScalarPrior& prior : p.input_priors) {
    prior = core::ScalarPrior::Box(-input_limit, input_limit).WithGaussian(0, 1);
  }
  for (int n = 1; n <= horizon; ++n) p.mutable_output_prior(n, 0) = core::ScalarPrior::Box(0, 1).WithGaussian(0.5, 1);
  return p;
}

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_BOUNDED_INTEGRATOR_H_
