#include "loadtest/failover_probe.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <mutex>
#include <thread>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "client/addressed_session.h"
#include "client/client.h"
#include "client/spec_update.h"
#include "core/nupmpc.h"
#include "loadtest/instances/benchmark_instance.h"
#include "loadtest/quantile.h"
#include "loadtest/twin_session.h"
#include "nlohmann/json.hpp"
#include "server/sessions/session_factory.h"

namespace nupmpc::loadtest {
namespace {

using Clock = std::chrono::steady_clock;

v1::Step StepFor(const std::vector<double>& state) {
  v1::Step step;
  step.mutable_state()->Add(state.begin(), state.end());
  return step;
}

std::string CodeName(const absl::Status& status) { return absl::StatusCodeToString(status.code()); }

// The largest difference between a converged plan and the core's own cold solve of the
// same spec from the same state, relative to the plan's size; NaN when the core did not
// converge (nothing to compare with).
double DifferenceFromCore(const v1::ProblemSpec& spec, const std::vector<double>& state,
                          const v1::SolveResult& result) {
  v1::ProblemSpec from_state = spec;
  from_state.mutable_initial_state()->mutable_mean()->Assign(state.begin(), state.end());
  absl::StatusOr<server::BuiltSession> built = server::BuildSession(from_state, bench::NoSizeLimits());
  if (!built.ok()) return std::nan("");
  core::Solution plan;
  core::SolveLimits cold;
  cold.warm_start = false;
  absl::StatusOr<core::SolveSummary> summary = built->solver->Solve(cold, &plan);
  if (!summary.ok() || summary->status != core::SolveStatus::kConverged) return std::nan("");
  const Eigen::Index L = plan.inputs.cols();
  if (result.inputs_size() != plan.inputs.size()) return std::numeric_limits<double>::infinity();
  double largest = 1.0, difference = 0.0;
  for (int i = 0; i < result.inputs_size(); ++i) {
    const double core_value = plan.inputs(i / L, i % L);
    largest = std::max(largest, std::abs(core_value));
    difference = std::max(difference, std::abs(result.inputs(i) - core_value));
  }
  return difference / largest;
}

// The largest |u - u'| over two plans' inputs (infinite when their sizes differ).
double LargestInputDifference(const v1::SolveResult& a, const v1::SolveResult& b) {
  if (a.inputs_size() != b.inputs_size()) return std::numeric_limits<double>::infinity();
  double largest = 0.0;
  for (int i = 0; i < a.inputs_size(); ++i) largest = std::max(largest, std::abs(a.inputs(i) - b.inputs(i)));
  return largest;
}

struct StreamOutcome {
  std::uint64_t steps = 0, failed = 0, no_plan = 0, verified = 0, mismatched = 0;
  std::uint64_t twin_compared = 0, twin_mismatched = 0;
  double max_difference = 0.0;
  std::map<std::string, std::uint64_t> errors;
  ReconnectStats reconnect;
  std::vector<double> round_trip_ms;
  std::vector<FirstStepAfterMove> first_steps;
};

void CountError(const absl::Status& status, StreamOutcome* out) {
  ++out->failed;
  ++out->errors[CodeName(status)];
}

StreamOutcome RunOneStream(const ProbeWorkload& work, const StreamsProbeConfig& config, int index,
                           Clock::time_point until) {
  StreamOutcome out;
  const bench::SessionKind& kind = work.kinds[static_cast<std::size_t>(index) % work.kinds.size()];
  // Its own connection, as a separate plant computer would have.
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(work.target, work.security);
  if (!client.ok()) {
    CountError(client.status(), &out);
    return out;
  }
  absl::StatusOr<std::unique_ptr<Session>> session = (*client)->OpenSession(kind.spec);
  absl::StatusOr<TwinSession> twin = TwinSession::Create(kind.spec);
  if (!session.ok() || !twin.ok()) {
    CountError(session.ok() ? twin.status() : session.status(), &out);
    return out;
  }
  // Streams start at different states, so they do not all solve the same step.
  std::size_t next = static_cast<std::size_t>(index) % work.states.size();
  // The spec as the client keeps it current (client/spec_update.h): what a re-create sends.
  v1::ProblemSpec carried = kind.spec;
  ReconnectStats seen;
  while (Clock::now() < until && (config.stop == nullptr || !config.stop->load())) {
    const std::vector<double>& state = work.states[next];
    next = (next + 1) % work.states.size();
    const v1::Step step = StepFor(state);
    const Clock::time_point sent = Clock::now();
    absl::StatusOr<v1::SolveResult> result = (*session)->Step(step);
    if (!result.ok()) {
      // Each failure on stderr: the report has the counts, the log says why.
      std::fprintf(stderr, "stream %d: step failed: %s\n", index, result.status().ToString().c_str());
      CountError(result.status(), &out);
      continue;
    }
    out.round_trip_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - sent).count());
    ++out.steps;
    // The session came back during this step: re-attached (the twin carries on) or
    // re-created cold from the spec the client carries (so is the twin: the old warm start is gone).
    const ReconnectStats now = (*session)->reconnect_stats();
    const bool resent = now.reconnects != seen.reconnects;
    const bool recreated = now.recreated != seen.recreated;
    seen = now;
    if (recreated) twin = TwinSession::Create(carried);
    absl::StatusOr<v1::SolveResult> expected = twin.ok() ? twin->Step(step) : twin.status();
    ++out.twin_compared;
    const bool same = expected.ok() && SamePlan(*result, *expected);
    if (!same) {
      ++out.twin_mismatched;
      std::fprintf(stderr, "stream %d (%s): plan differs from its twin's (passes %u, twin %s)\n", index,
                   kind.name.c_str(), result->iterations(),
                   expected.ok() ? absl::StrCat(expected->iterations()).c_str() : expected.status().ToString().c_str());
    }
    if (resent) {
      FirstStepAfterMove first{kind.name, !recreated, result->iterations(), expected.ok() ? expected->iterations() : 0};
      absl::StatusOr<TwinSession> cold = TwinSession::Create(carried);
      absl::StatusOr<v1::SolveResult> cold_result = cold.ok() ? cold->Step(step) : cold.status();
      if (cold_result.ok()) first.cold_passes = cold_result->iterations();
      first.cold_same_as_twin = cold_result.ok() && expected.ok() && SamePlan(*cold_result, *expected);
      first.cold_difference = cold_result.ok() && expected.ok() ? LargestInputDifference(*cold_result, *expected)
                                                                : std::numeric_limits<double>::infinity();
      first.same_as_twin = same;
      out.first_steps.push_back(first);
    }
    ApplyStepToSpec(step, *result, &carried);
    if (!HasPlan(*result)) {
      ++out.no_plan;
      continue;
    }
    // Convex plans are also held to the core's own cold solve (a unique optimum): the step
    // resent after a reconnect always, others sampled.
    const bool sampled = config.verify_every > 0 && out.steps % static_cast<std::uint64_t>(config.verify_every) == 0;
    if (kind.name == "convex" && (resent || sampled) && result->status() == v1::SOLVE_STATUS_CONVERGED) {
      const double difference = DifferenceFromCore(kind.spec, state, *result);
      if (!std::isnan(difference)) {
        ++out.verified;
        out.max_difference = std::max(out.max_difference, difference);
        if (!(difference <= 1e-9)) ++out.mismatched;
      }
    }
  }
  out.reconnect = (*session)->reconnect_stats();
  (void)(*session)->Close();
  return out;
}

}  // namespace

absl::StatusOr<StreamsProbeReport> RunStreamsProbe(const ProbeWorkload& work, const StreamsProbeConfig& config) {
  if (config.streams < 1) return absl::InvalidArgumentError("streams: must be at least 1");
  if (work.states.empty()) return absl::InvalidArgumentError("the instance has no states to send");
  ProbeWorkload with_kinds = work;
  if (with_kinds.kinds.empty()) with_kinds.kinds.push_back({"convex", work.spec});
  const Clock::time_point start = Clock::now();
  const Clock::time_point until =
      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config.duration_s));
  std::vector<StreamOutcome> outcomes(static_cast<std::size_t>(config.streams));
  std::vector<std::thread> threads;
  threads.reserve(static_cast<std::size_t>(config.streams));
  for (int i = 0; i < config.streams; ++i) {
    threads.emplace_back(
        [&, i] { outcomes[static_cast<std::size_t>(i)] = RunOneStream(with_kinds, config, i, until); });
  }
  for (std::thread& t : threads) t.join();
  const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();

  StreamsProbeReport report;
  report.streams = config.streams;
  std::vector<double> round_trips;
  for (const StreamOutcome& o : outcomes) {
    report.steps += o.steps;
    report.failed_steps += o.failed;
    report.no_plan += o.no_plan;
    for (const auto& [code, n] : o.errors) report.errors[code] += n;
    report.reconnects += o.reconnect.reconnects;
    report.reattached += o.reconnect.reattached;
    report.recreated += o.reconnect.recreated;
    report.longest_outage_s = std::max(report.longest_outage_s, o.reconnect.longest.count() / 1000.0);
    if (o.reconnect.reconnects > 0 || o.reconnect.attempts > 0 || o.failed > 0) {
      ++report.affected_streams;
      report.max_failed_per_affected = std::max(report.max_failed_per_affected, o.failed);
    }
    report.verified += o.verified;
    report.mismatched += o.mismatched;
    report.max_plan_difference = std::max(report.max_plan_difference, o.max_difference);
    report.twin_compared += o.twin_compared;
    report.twin_mismatched += o.twin_mismatched;
    report.first_steps.insert(report.first_steps.end(), o.first_steps.begin(), o.first_steps.end());
    round_trips.insert(round_trips.end(), o.round_trip_ms.begin(), o.round_trip_ms.end());
  }
  report.solves_per_s = static_cast<double>(report.steps) / std::max(elapsed_s, 1e-9);
  report.p50_ms = Quantile(round_trips, 0.50);
  report.p99_ms = Quantile(round_trips, 0.99);
  return report;
}

absl::StatusOr<AddressedProbeReport> RunAddressedProbe(const ProbeWorkload& work, int sessions, int solves_each) {
  if (sessions < 1 || solves_each < 1) return absl::InvalidArgumentError("sessions, solves: must be at least 1");
  absl::StatusOr<std::unique_ptr<Client>> connected = Client::Connect(work.target, work.security);
  if (!connected.ok()) return connected.status();
  Client& client = **connected;
  AddressedProbeReport report;
  report.sessions = sessions;
  std::vector<std::unique_ptr<AddressedSession>> opened;
  for (int i = 0; i < sessions; ++i) {
    absl::StatusOr<std::unique_ptr<AddressedSession>> s = AddressedSession::Create(&client, work.spec);
    if (!s.ok())
      return absl::Status(s.status().code(), absl::StrCat("creating session ", i + 1, ": ", s.status().message()));
    opened.push_back(*std::move(s));
  }
  // Round by round, so consecutive calls of one session are far apart and interleaved
  // with every other session's.
  for (int round = 0; round < solves_each; ++round) {
    for (std::size_t i = 0; i < opened.size(); ++i) {
      const std::vector<double>& state = work.states[(i + static_cast<std::size_t>(round)) % work.states.size()];
      absl::StatusOr<v1::SolveResult> result = opened[i]->Step(StepFor(state));
      if (result.ok()) {
        ++report.solves;
      } else {
        ++report.failed;
        ++report.errors[CodeName(result.status())];
      }
    }
  }
  for (const std::unique_ptr<AddressedSession>& s : opened) {
    report.reattached += s->reconnect_stats().reattached;
    report.recreated += s->reconnect_stats().recreated;
    absl::StatusOr<v1::SessionInfo> info = client.GetSession(s->id());
    if (!info.ok() || info->solves() != static_cast<std::uint64_t>(solves_each)) ++report.miscounted;
  }
  return report;
}

// One entry per move (the first step after it), and per kind and way back: how many moved,
// how many plans equalled the twin's (the server's, and a cold re-create's), how far a cold
// re-create's inputs were from the twin's at most, and the passes summed (server, twin, cold).
nlohmann::json FirstStepsJson(const std::vector<FirstStepAfterMove>& steps) {
  nlohmann::json by = nlohmann::json::object();
  for (const FirstStepAfterMove& f : steps) {
    nlohmann::json& k = by[f.kind][f.reattached ? "reattached" : "recreated"];
    if (k.is_null()) {
      k = {{"moved", 0},  {"same_as_twin", 0}, {"cold_same_as_twin", 0}, {"cold_max_difference", 0.0},
           {"passes", 0}, {"twin_passes", 0},  {"cold_passes", 0}};
    }
    k["moved"] = k["moved"].get<int>() + 1;
    k["same_as_twin"] = k["same_as_twin"].get<int>() + (f.same_as_twin ? 1 : 0);
    k["cold_same_as_twin"] = k["cold_same_as_twin"].get<int>() + (f.cold_same_as_twin ? 1 : 0);
    k["cold_max_difference"] = std::max(k["cold_max_difference"].get<double>(), f.cold_difference);
    k["passes"] = k["passes"].get<unsigned>() + f.passes;
    k["twin_passes"] = k["twin_passes"].get<unsigned>() + f.twin_passes;
    k["cold_passes"] = k["cold_passes"].get<unsigned>() + f.cold_passes;
  }
  return by;
}

std::string ToJson(const StreamsProbeReport& r) {
  nlohmann::json j = {{"probe", "streams"},
                      {"streams", r.streams},
                      {"steps", r.steps},
                      {"failed_steps", r.failed_steps},
                      {"no_plan", r.no_plan},
                      {"errors", r.errors},
                      {"affected_streams", r.affected_streams},
                      {"max_failed_per_affected_stream", r.max_failed_per_affected},
                      {"reconnects", r.reconnects},
                      {"reattached", r.reattached},
                      {"recreated", r.recreated},
                      {"longest_outage_s", r.longest_outage_s},
                      {"verified", r.verified},
                      {"mismatched", r.mismatched},
                      {"max_plan_difference", r.max_plan_difference},
                      {"twin_compared", r.twin_compared},
                      {"twin_mismatched", r.twin_mismatched},
                      {"first_steps_after_move", FirstStepsJson(r.first_steps)},
                      {"solves_per_s", r.solves_per_s},
                      {"p50_ms", r.p50_ms},
                      {"p99_ms", r.p99_ms}};
  return j.dump();
}

std::string ToJson(const AddressedProbeReport& r) {
  nlohmann::json j = {{"probe", "addressed"},     {"sessions", r.sessions},    {"solves", r.solves},
                      {"failed", r.failed},       {"errors", r.errors},        {"reattached", r.reattached},
                      {"recreated", r.recreated}, {"miscounted", r.miscounted}};
  return j.dump();
}

}  // namespace nupmpc::loadtest
