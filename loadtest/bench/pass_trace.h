#ifndef NUPMPC_LOADTEST_BENCH_PASS_TRACE_H_
#define NUPMPC_LOADTEST_BENCH_PASS_TRACE_H_

#include <string>

#include "core/public/session.h"

namespace nupmpc::bench {

// nupmpc-bench --trace: one cold solve of `session` whose every pass is printed (kind,
// region changes, objective and violation of an iterate, residual of a polish round), as
// lines under the instance's row or, with `json`, one object per pass.
void PrintPassTrace(const std::string& name, core::Session& session, bool json);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_PASS_TRACE_H_
