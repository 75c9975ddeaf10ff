#ifndef NUPMPC_CORE_PROBLEM_H_
#define NUPMPC_CORE_PROBLEM_H_

#include <optional>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "core/priors/scalar_prior.h"

namespace nupmpc::core {

// A linear MPC problem over horizon N (nup-algorithms.md §2, 0-based):
//
//   x[n+1] = A[n] x[n] + B[n] u[n] + c[n]      n = 0..N-1
//   y[n]   = C[n] x[n] + d[n]                  n = 0..N
//   x[0] fixed (initial_covariance empty or zero) or x[0] ~ N(initial_mean, initial_covariance)
//
// with one ScalarPrior per input component per step and per output component per
// step, and an optional terminal cost ½(x[N]-x_f)ᵀ Qf (x[N]-x_f). The objective is
//   J = [½(x0-m0)ᵀV0⁻¹(x0-m0)] + Σ φ_u + Σ φ_y + terminal
// (φ = Gaussian part + penalty of finite-slope kinds; hard constraints add no cost).
//
// Time-invariant models give one matrix; time-varying ones give one per step
// (A, B, c: N entries; C, d: N+1 entries). Empty offsets mean zero.
struct Problem {
  int num_states = 0;   ///< M
  int num_inputs = 0;   ///< L
  int num_outputs = 0;  ///< K (per step, same at every step; unused rows carry a free prior)
  int horizon = 0;      ///< N ≥ 1

  std::vector<Eigen::MatrixXd> A;              ///< 1 or N matrices, M×M
  std::vector<Eigen::MatrixXd> B;              ///< 1 or N matrices, M×L
  std::vector<Eigen::MatrixXd> C;              ///< 1 or N+1 matrices, K×M
  std::vector<Eigen::VectorXd> state_offset;   ///< c: empty, 1 or N vectors of size M
  std::vector<Eigen::VectorXd> output_offset;  ///< d: empty, 1 or N+1 vectors of size K

  Eigen::VectorXd initial_mean;        ///< m0 (size M): the measured state when fixed
  Eigen::MatrixXd initial_covariance;  ///< V0 (M×M, symmetric positive definite) or empty = fixed

  std::vector<ScalarPrior> input_priors;   ///< N·L, index n·L + l
  std::vector<ScalarPrior> output_priors;  ///< (N+1)·K, index n·K + k

  struct Terminal {
    Eigen::VectorXd target;  ///< x_f (size M)
    Eigen::MatrixXd weight;  ///< Qf (M×M, symmetric positive semidefinite)
  };
  std::optional<Terminal> terminal;

  bool initial_state_fixed() const { return initial_covariance.size() == 0 || initial_covariance.isZero(0.0); }
  const Eigen::MatrixXd& A_at(int n) const { return A.size() == 1 ? A[0] : A[n]; }
  const Eigen::MatrixXd& B_at(int n) const { return B.size() == 1 ? B[0] : B[n]; }
  const Eigen::MatrixXd& C_at(int n) const { return C.size() == 1 ? C[0] : C[n]; }
  double state_offset_at(int n, int i) const {
    if (state_offset.empty()) return 0.0;
    return (state_offset.size() == 1 ? state_offset[0] : state_offset[n])(i);
  }
  double output_offset_at(int n, int k) const {
    if (output_offset.empty()) return 0.0;
    return (output_offset.size() == 1 ? output_offset[0] : output_offset[n])(k);
  }
  const ScalarPrior& input_prior(int n, int l) const { return input_priors[n * num_inputs + l]; }
  const ScalarPrior& output_prior(int n, int k) const { return output_priors[n * num_outputs + k]; }
  ScalarPrior& mutable_input_prior(int n, int l) { return input_priors[n * num_inputs + l]; }
  ScalarPrior& mutable_output_prior(int n, int k) { return output_priors[n * num_outputs + k]; }

  // Convenience: sizes the prior arrays (all free) and the model vectors for a
  // time-invariant problem. Matrices are left for the caller to fill.
  static Problem TimeInvariant(int M, int L, int K, int N);
};

// Checks every field; the message names the field, its value and the broken rule,
// e.g. "Problem.A[3]: expected 4x4, got 4x3".
absl::Status Validate(const Problem& problem);

// The prior arrays' part of Validate: their sizes, each prior, and CheckPriorGrouping.
absl::Status ValidatePriors(const Problem& problem);
// How the priors of one step combine: binaries grouped into an M-level input
// (rounds_with_next) are binaries with the same levels; outputs are never grouped.
absl::Status CheckPriorGrouping(const Problem& problem);

// FAILED_PRECONDITION unless `update` has `session`'s shape: dimensions, horizon, which
// matrices vary per step, terminal cost present. A session's problem may only be replaced
// by one of the same shape.
absl::Status CheckSameShape(const Problem& session, const Problem& update);

// A new measured x[0] for a session of `session`'s shape: FAILED_PRECONDITION for a wrong
// size, INVALID_ARGUMENT for non-finite values.
absl::Status CheckInitialState(const Problem& session, const Eigen::VectorXd& x0);

// Checks one scalar prior; `field` is the path used in the message.
absl::Status ValidatePrior(const ScalarPrior& prior, const char* field, int index);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_PROBLEM_H_
