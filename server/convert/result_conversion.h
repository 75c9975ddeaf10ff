#ifndef NUPMPC_SERVER_CONVERT_RESULT_CONVERSION_H_
#define NUPMPC_SERVER_CONVERT_RESULT_CONVERSION_H_

// core → proto: what a solve sends back.

#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// Fills a SolveResult from the core's summary and solution (the plan only when the
// summary has one: SolveResult.has_plan).
void ResultToProto(const core::SolveSummary& summary, const core::Solution& solution, v1::SolveResult* out);

v1::Algorithm AlgorithmToProto(core::Algorithm algorithm);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_RESULT_CONVERSION_H_
