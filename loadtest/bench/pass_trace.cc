#include "loadtest/bench/pass_trace.h"

#include <cstdio>

#include "loadtest/bench/instance_result.h"

namespace nupmpc::bench {

void PrintPassTrace(const std::string& name, core::Session& session, bool json) {
  core::SolveLimits limits;
  limits.warm_start = false;
  limits.trace = [&](const core::PassTrace& t) {
    const bool polish = t.kind == core::PassTrace::Kind::kPolish;
    if (json) {
      std::printf(
          "{\"trace\":\"%s\",\"pass\":%d,\"kind\":\"%s\",\"changed\":%d,\"objective\":%s,"
          "\"max_violation\":%s,\"residual\":%s}\n",
          name.c_str(), t.pass, polish ? "polish" : "iterate", t.changed, Num(t.objective).c_str(),
          Num(t.max_violation).c_str(), Num(t.residual).c_str());
    } else if (polish) {
      std::printf("  pass %4d  polish   residual %.3e\n", t.pass, t.residual);
    } else {
      std::printf("  pass %4d  iterate  %6d changed  J %.12g  violation %.3e\n", t.pass, t.changed, t.objective,
                  t.max_violation);
    }
  };
  const absl::StatusOr<core::SolveSummary> s = session.Solve(limits, nullptr);
  if (!s.ok()) {
    std::fprintf(stderr, "nupmpc-bench: %s: traced solve: %s\n", name.c_str(), s.status().ToString().c_str());
  }
}

}  // namespace nupmpc::bench
