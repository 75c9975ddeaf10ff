#include "core/algorithms/select.h"

#include "core/algorithms/iake.h"
#include "core/algorithms/ibffd.h"
#include "core/algorithms/iffbdd.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

absl::Status CheckApplicable(const Problem& p, Algorithm a) {
  switch (a) {
    case Algorithm::kIake:
      return Iake::CheckApplicable(p);
    case Algorithm::kIbffd:
      return Ibffd::CheckApplicable(p);
    case Algorithm::kIffbdd:
      return Iffbdd::CheckApplicable(p);
    case Algorithm::kAuto:
      break;
  }
  return absl::InternalError("CheckApplicable(kAuto)");
}

}  // namespace

absl::StatusOr<Algorithm> SelectAlgorithm(const Problem& p, Algorithm requested) {
  if (requested != Algorithm::kAuto) {
    NUPMPC_RETURN_IF_ERROR(CheckApplicable(p, requested));
    return requested;
  }
  for (Algorithm a : {Algorithm::kIbffd, Algorithm::kIffbdd, Algorithm::kIake}) {
    if (CheckApplicable(p, a).ok()) return a;
  }
  return absl::FailedPreconditionError(
      "no algorithm applies: outputs are constrained and some input has neither a Gaussian part nor a "
      "constraint (give every input a prior, e.g. a weight R > 0)");
}

absl::StatusOr<std::unique_ptr<OuterIteration>> MakeOuterIteration(const Problem& p, const SolverOptions& options) {
  NUPMPC_ASSIGN_OR_RETURN(const Algorithm a, SelectAlgorithm(p, options.algorithm));
  switch (a) {
    case Algorithm::kIake:
      return std::unique_ptr<OuterIteration>(new Iake(p, options));
    case Algorithm::kIbffd:
      return std::unique_ptr<OuterIteration>(new Ibffd(p, options));
    case Algorithm::kIffbdd:
      return std::unique_ptr<OuterIteration>(new Iffbdd(p, options));
    case Algorithm::kAuto:
      break;
  }
  return absl::InternalError("SelectAlgorithm returned kAuto");
}

}  // namespace nupmpc::core
