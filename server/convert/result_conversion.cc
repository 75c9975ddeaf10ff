#include "server/convert/result_conversion.h"

#include <cstdint>
#include <limits>

namespace nupmpc::server {

v1::Algorithm AlgorithmToProto(core::Algorithm a) {
  switch (a) {
    case core::Algorithm::kIake:
      return v1::ALGORITHM_IAKE;
    case core::Algorithm::kIbffd:
      return v1::ALGORITHM_IBFFD;
    case core::Algorithm::kIffbdd:
      return v1::ALGORITHM_IFFBDD;
    case core::Algorithm::kAuto:
      break;
  }
  return v1::ALGORITHM_UNSPECIFIED;
}

namespace {
v1::SolveStatus StatusToProto(core::SolveStatus s) {
  switch (s) {
    case core::SolveStatus::kConverged:
      return v1::SOLVE_STATUS_CONVERGED;
    case core::SolveStatus::kIterationLimit:
      return v1::SOLVE_STATUS_ITERATION_LIMIT;
    case core::SolveStatus::kTimeLimit:
      return v1::SOLVE_STATUS_TIME_LIMIT;
    case core::SolveStatus::kNumericalError:
      return v1::SOLVE_STATUS_NUMERICAL_ERROR;
    case core::SolveStatus::kCancelled:
      return v1::SOLVE_STATUS_CANCELLED;
    case core::SolveStatus::kInfeasible:
      return v1::SOLVE_STATUS_INFEASIBLE;
  }
  return v1::SOLVE_STATUS_UNSPECIFIED;
}

// Row-major (step-major) copy of a matrix whose rows are steps.
void CopyRows(const Eigen::MatrixXd& m, google::protobuf::RepeatedField<double>* out) {
  out->Resize(static_cast<int>(m.size()), 0.0);
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(out->mutable_data(), m.rows(),
                                                                                     m.cols()) = m;
}
}  // namespace

void ResultToProto(const core::SolveSummary& s, const core::Solution& solution, v1::SolveResult* out) {
  out->set_status(StatusToProto(s.status));
  out->set_iterations(static_cast<unsigned>(s.iterations));
  const bool has_plan = s.has_plan;
  out->set_has_plan(has_plan);
  out->set_objective(has_plan ? s.objective : std::numeric_limits<double>::quiet_NaN());
  out->set_max_violation(has_plan ? s.max_violation : std::numeric_limits<double>::quiet_NaN());
  out->set_solve_ms(s.solve_seconds * 1e3);
  out->set_algorithm(AlgorithmToProto(s.algorithm));
  out->set_warm_started(s.warm_started);
  out->set_polished(s.polished);
  out->set_rounded(s.rounded);
  out->set_discrete_gap(s.discrete_gap);
  out->set_discrete_moves(static_cast<uint32_t>(s.discrete_moves));
  out->set_linearisations(static_cast<unsigned>(s.linearisations));
  out->set_keep_out_violation(s.nonlinear_violation);
  // Without a plan for this step's state nothing of one is sent (SolveResult.has_plan).
  if (!has_plan) return;
  CopyRows(solution.inputs, out->mutable_inputs());
  CopyRows(solution.outputs, out->mutable_outputs());
  CopyRows(solution.states, out->mutable_states());
  CopyRows(solution.output_stddev, out->mutable_output_stddev());
}

}  // namespace nupmpc::server
