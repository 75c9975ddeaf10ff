#ifndef NUPMPC_CORE_ALGORITHMS_OBJECTIVE_H_
#define NUPMPC_CORE_ALGORITHMS_OBJECTIVE_H_

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "core/algorithms/interrupt.h"
#include "core/algorithms/primal_iterate.h"
#include "core/problem.h"

namespace nupmpc::core {

// Simulates a primal iterate (x[0], u) through the model and evaluates the objective J
// (nup-algorithms.md §2; the benchmark convention with constants) and the largest
// violation of a hard constraint. Independent of the message passing: it works on the
// Problem itself, so it also checks the algorithms.
class ObjectiveEvaluator {
 public:
  struct Result {
    double objective = 0.0;
    double max_violation = 0.0;
  };

  // Allocates the trajectories and factors V0 (call again after the problem changes).
  void Prepare(const Problem& problem);
  // `interrupt` (may be null) is polled along the horizon (interrupt.h); once it fired the
  // result is {NaN, NaN} and the trajectories are partial.
  Result Evaluate(const Problem& problem, const PrimalIterate& iterate, Interrupt* interrupt = nullptr);

  // Trajectories of the last Evaluate(): states M × (N+1), outputs K × (N+1).
  const Eigen::MatrixXd& states() const { return x_; }
  const Eigen::MatrixXd& outputs() const { return y_; }
  // Largest finite bound magnitude of the hard constraints (1 if none is nonzero): the
  // scale of the relative violation tolerance.
  double bound_scale() const { return bound_scale_; }

 private:
  // False if interrupted.
  template <int MS>
  bool Simulate(const Problem& problem, const PrimalIterate& iterate, Interrupt* interrupt);

  Eigen::MatrixXd x_, y_;
  Eigen::VectorXd dx_, tmp_;
  Eigen::LLT<Eigen::MatrixXd> v0_llt_;
  bool x0_free_ = false;
  double bound_scale_ = 1.0;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_ALGORITHMS_OBJECTIVE_H_
