#ifndef NUPMPC_LOADTEST_INSTANCES_SPEC_FROM_PROBLEM_H_
#define NUPMPC_LOADTEST_INSTANCES_SPEC_FROM_PROBLEM_H_

// The spec builder of the tests and tools: the v1::ProblemSpec of a core problem (the
// reverse of server::ProblemFromSpec; the service itself never needs this direction).

#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::bench {

// Fails when a component mixes prior kinds that one ComponentPrior cannot express.
absl::StatusOr<v1::ProblemSpec> SpecFromProblem(const core::Problem& problem);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_INSTANCES_SPEC_FROM_PROBLEM_H_
