#ifndef NUPMPC_TESTS_UTIL_DENSE_REFERENCE_H_
#define NUPMPC_TESTS_UTIL_DENSE_REFERENCE_H_

#include "Eigen/Core"
#include "core/problem.h"

namespace nupmpc::testing {

// The exact Gaussian posterior of a problem whose priors are all Gaussian (or free), by
// dense linear algebra on the stacked least-squares problem over z = (x0 if free, u).
// Independent of the message passing: the reference for the recursions.
struct DensePosterior {
  Eigen::VectorXd x0_mean;
  Eigen::MatrixXd x0_cov;  ///< zero when x0 is fixed
  Eigen::MatrixXd u_mean;  ///< L × N
  Eigen::MatrixXd u_var;   ///< L × N
  Eigen::MatrixXd y_mean;  ///< K × (N+1), outputs including offsets
  Eigen::MatrixXd y_var;   ///< K × (N+1)
  double objective = 0.0;  ///< J at the posterior mean
};

DensePosterior SolveDense(const core::Problem& problem);

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_DENSE_REFERENCE_H_
