#include "loadtest/twin_session.h"

#include <cstring>

#include "loadtest/instances/benchmark_instance.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_solver.h"

namespace nupmpc::loadtest {

absl::StatusOr<TwinSession> TwinSession::Create(const v1::ProblemSpec& spec) {
  server::CallContext call;
  absl::StatusOr<server::BuiltSession> built = server::BuildSession(spec, bench::NoSizeLimits(), nullptr, &call);
  if (!built.ok()) return built.status();
  auto entry = std::make_shared<server::SessionEntry>();
  entry->solver = std::move(built->solver);
  entry->timing = built->timing;
  return TwinSession(std::move(entry));
}

absl::StatusOr<v1::SolveResult> TwinSession::Step(const v1::Step& step) {
  server::CallContext call;
  v1::SolveResult result;
  if (absl::Status s = server::SolveStep(*entry_, step, call, &result); !s.ok()) return s;
  return result;
}

bool SamePlan(const v1::SolveResult& a, const v1::SolveResult& b) {
  if (a.has_plan() != b.has_plan() || a.iterations() != b.iterations()) return false;
  if (a.inputs_size() != b.inputs_size()) return false;
  return a.inputs_size() == 0 || std::memcmp(a.inputs().data(), b.inputs().data(),
                                             sizeof(double) * static_cast<std::size_t>(a.inputs_size())) == 0;
}

}  // namespace nupmpc::loadtest
