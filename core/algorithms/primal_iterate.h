#ifndef NUPMPC_CORE_ALGORITHMS_PRIMAL_ITERATE_H_
#define NUPMPC_CORE_ALGORITHMS_PRIMAL_ITERATE_H_

#include "Eigen/Core"

namespace nupmpc::core {

// The primal iterate every algorithm produces: x[0] and the inputs (L × N, column n = u[n]).
struct PrimalIterate {
  Eigen::VectorXd x0;
  Eigen::MatrixXd u;
  void Resize(int M, int L, int N) {
    x0.setZero(M);
    u.setZero(L, N);
  }
};

inline bool AllFinite(const PrimalIterate& it) { return it.x0.allFinite() && it.u.allFinite(); }

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_PRIMAL_ITERATE_H_
