// Fuzz target (a): a serialized ProblemSpec → validation → session build → one solve with
// a small iteration cap (what SolveOnce does). Properties: no crash or sanitizer report,
// bounded work per input (the limits refuse sizes before allocating), no NaN or infinity in
// a returned plan.
#include <cstddef>
#include <cstdint>

#include "server/sessions/call_context.h"
#include "server/sessions/step_solver.h"
#include "tests/fuzz/fuzz_limits.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nupmpc::v1::ProblemSpec spec;
  if (!spec.ParseFromArray(data, static_cast<int>(size))) return 0;
  // Every input solves with a small cap, whatever it asks for.
  spec.mutable_options()->set_max_iterations(std::min<std::uint32_t>(spec.options().max_iterations(), 20));
  if (spec.options().max_iterations() == 0) spec.mutable_options()->set_max_iterations(20);
  nupmpc::server::CallContext call;
  call.deadline = nupmpc::server::Clock::now() + std::chrono::milliseconds(500);
  nupmpc::v1::SolveResult result;
  const absl::Status status = nupmpc::server::SolveOnce(spec, nupmpc::fuzz::SmallLimits(), call, &result);
  if (status.ok()) nupmpc::fuzz::CheckResult(result);
  if (!status.ok() && status.message().empty()) nupmpc::fuzz::Violated("an error without a message");
  return 0;
}
