// Fuzz target (b): a session (a small masses-like problem with input and output boxes and
// a terminal cost) plus a serialized Step: updates, shifts, states, references. Properties:
// no crash or sanitizer report, no NaN or infinity in a plan, and a refused step leaves
// the session bit-identical (a cold solve of a fixed state before and after it gives the
// same plan, to the last bit).
#include <cstddef>
#include <cstdint>
#include <memory>

#include "server/sessions/call_context.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_solver.h"
#include "tests/fuzz/fuzz_limits.h"
#include "tests/fuzz/seed_problem.h"

namespace {

using nupmpc::server::SessionEntry;

std::shared_ptr<SessionEntry> NewSession() {
  nupmpc::server::CallContext call;
  absl::StatusOr<nupmpc::server::BuiltSession> built =
      nupmpc::server::BuildSession(nupmpc::fuzz::SeedSpec(), nupmpc::fuzz::SmallLimits(), nullptr, &call);
  if (!built.ok()) nupmpc::fuzz::Violated("the seed spec does not build");
  auto entry = std::make_shared<SessionEntry>();
  entry->solver = std::move(built->solver);
  entry->timing = built->timing;
  return entry;
}

nupmpc::v1::SolveResult ColdSolve(SessionEntry& entry) {
  nupmpc::v1::Step step = nupmpc::fuzz::SeedStep(0);
  step.set_warm_start(nupmpc::v1::WARM_START_COLD);
  nupmpc::server::CallContext call;
  nupmpc::v1::SolveResult result;
  if (!nupmpc::server::SolveStep(entry, step, call, &result).ok()) nupmpc::fuzz::Violated("the fixed step fails");
  return result;
}

bool BitIdentical(const nupmpc::v1::SolveResult& a, const nupmpc::v1::SolveResult& b) {
  return a.SerializeAsString() == b.SerializeAsString();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nupmpc::v1::Step step;
  if (!step.ParseFromArray(data, static_cast<int>(size))) return 0;
  if (step.max_iterations() == 0 || step.max_iterations() > 20) step.set_max_iterations(20);
  static std::shared_ptr<SessionEntry> session = NewSession();
  nupmpc::v1::SolveResult before = ColdSolve(*session);
  before.clear_solve_ms();
  nupmpc::server::CallContext call;
  call.deadline = nupmpc::server::Clock::now() + std::chrono::milliseconds(500);
  nupmpc::v1::SolveResult result;
  const absl::Status status = nupmpc::server::SolveStep(*session, step, call, &result);
  if (status.ok()) {
    nupmpc::fuzz::CheckResult(result);
    session = NewSession();  // the step changed the session: the next input starts afresh
    return 0;
  }
  if (status.message().empty()) nupmpc::fuzz::Violated("an error without a message");
  nupmpc::v1::SolveResult after = ColdSolve(*session);
  after.clear_solve_ms();
  if (!BitIdentical(before, after)) nupmpc::fuzz::Violated("a refused step changed the session");
  return 0;
}
