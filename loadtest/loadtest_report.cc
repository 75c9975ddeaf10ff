#include "loadtest/loadtest_report.h"

#include <algorithm>
#include <cstdio>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "nlohmann/json.hpp"
#include "server/scheduling/cpu_affinity.h"

namespace nupmpc::loadtest {
namespace {

std::string Errors(const StreamTally& t) {
  if (t.errors.empty()) return "none";
  return absl::StrJoin(t.errors, " ",
                       [](std::string* out, const auto& e) { absl::StrAppend(out, e.first, ":", e.second); });
}

// Round trip above the core's own median: what the network, gRPC and the server add.
double OverheadUs(const RunHeader& h, const LevelReport& l) { return (l.p50_ms - h.baseline.median_ms) * 1e3; }

nlohmann::json PeerJson(const LevelReport& e) {
  return {{"solves_per_s", e.solves_per_s},
          {"p50_ms", e.p50_ms},
          {"p90_ms", e.p90_ms},
          {"p99_ms", e.p99_ms},
          {"p999_ms", e.p999_ms},
          {"max_ms", e.max_ms},
          {"superseded", e.tally.superseded},
          {"no_plan", e.tally.no_plan},
          {"errors", e.tally.errors}};
}

// The server's level against a peer's run of it.
nlohmann::json VersusPeerJson(const LevelReport& l, const LevelReport& peer) {
  return {{"solves_ratio", l.solves_per_s / peer.solves_per_s},
          {"p50_delta_us", (l.p50_ms - peer.p50_ms) * 1e3},
          {"p99_ratio", l.p99_ms / peer.p99_ms}};
}

// One table row; the server's and the peers' rows differ in the label, the iterations and
// the capacity columns (a peer does no solve) and in what the overhead is measured from.
void PrintRow(const char* label, const LevelReport& l, const std::string& iterations, double overhead_us,
              const std::string& capacity) {
  const std::string offered = l.config.closed_loop ? "-" : absl::StrCat(static_cast<long long>(l.config.rate_per_s));
  std::printf("%5d %-6s %10s %10.0f %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f %6s %10llu %7llu %8.0f\xc2\xb5s %9s  %s\n",
              l.config.concurrency, label, offered.c_str(), l.solves_per_s, l.p50_ms, l.p90_ms, l.p99_ms, l.p999_ms,
              l.max_ms, l.service_p99_ms, iterations.c_str(), static_cast<unsigned long long>(l.tally.superseded),
              static_cast<unsigned long long>(l.tally.no_plan), overhead_us, capacity.c_str(), Errors(l.tally).c_str());
  std::fflush(stdout);
}

double MiB(std::uint64_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }

}  // namespace

int UsableCores(int cores, const std::string& cpus) {
  if (cpus.empty()) return cores;
  const absl::StatusOr<cpu_set_t> set = server::ParseCpuList(cpus);
  if (!set.ok()) return cores;
  return std::max(1, std::min(cores, CPU_COUNT(&*set)));
}

void PrintHeader(const RunHeader& h) {
  std::printf("nupmpc-loadtest: %s against %s (nupmpc-server %s, %u workers, %u solver cores, queue %u)\n",
              h.instance.c_str(), h.target.c_str(), h.server.version().c_str(), h.server.limits().worker_threads(),
              h.server.limits().solver_cores(), h.server.limits().queue_capacity());
  std::printf(
      "core alone, same steps: median %.4f ms, mean %.4f ms, p99 %.4f ms, %.2f iterations/step over %d "
      "solves; capacity %d cores / median = %.0f solves/s (solver cores on the server's CPUs)\n",
      h.baseline.median_ms, h.baseline.mean_ms, h.baseline.p99_ms, h.baseline.mean_iterations, h.baseline.solves,
      h.solve_cores, h.capacity_per_s);
  std::printf(
      "transport alone (grpc.health.v1 Check, answered inside gRPC): p50 %.0f \xc2\xb5s, p99 %.0f \xc2\xb5s "
      "over %d calls\n",
      h.transport.p50_us, h.transport.p99_us, h.transport.calls);
  std::printf("CPUs: nupmpc-server %s (as it reports), echo peers and core baseline %s, load generator %s\n",
              h.server.cpus().empty() ? "?" : h.server.cpus().c_str(),
              h.peer_cpus.empty() ? "not pinned" : h.peer_cpus.c_str(), h.generator_cpus.c_str());
  if (h.rounds > 1 && (h.echo || h.inline_solve || h.bare)) {
    std::printf(
        "(each level: %d rounds against nupmpc and each peer in turn, the order reversed every round, "
        "merged per server)\n",
        h.rounds);
  }
  std::printf(
      "(latency is request sent, or open-loop arrival scheduled, to answer received; svc: from the "
      "hand-over to gRPC)\n");
  if (h.echo) {
    std::printf(
        "(echo rows: the same level against a zero-work server, a process of its own, that answers every "
        "step at once with a real plan: the transport floor at that load, overhead = its p50)\n");
  }
  if (h.bare) {
    std::printf(
        "(bare rows: a bare server, a process of its own, that builds each stream's session from its spec "
        "and solves each step in its reaction as nupmpc-server's SolveStep does, with nothing else: no "
        "worker pool, session registry, admission, deadlines, metrics; overhead = its p50 - the core "
        "median)\n");
  }
  if (h.inline_solve) {
    std::printf(
        "(inline rows: the same echo, busy inside its reaction before it answers, for each step the core's "
        "own time for that step (measured with as many sessions stepped in turn as the level has streams): a "
        "server that solves where the request arrives, with no hand-over and nothing else; overhead = its "
        "p50 - that core median)\n");
  }
  std::printf(
      "(no plan: answers without SolveResult.has_plan, whose inputs a controller must not apply; the load "
      "test sends recorded states and applies no input)\n");
  std::printf("%5s %-6s %10s %10s %8s %8s %8s %8s %8s %8s %6s %10s %7s %10s %9s  %s\n", "C", "mode", "offered/s",
              "solves/s", "p50 ms", "p90 ms", "p99 ms", "p99.9 ms", "max ms", "svc p99", "iter", "superseded",
              "no plan", "overhead", "capacity", "errors");
}

void PrintLevel(const RunHeader& h, const LevelReport& l) {
  PrintRow(l.config.closed_loop ? "closed" : "open", l, absl::StrFormat("%.2f", l.mean_iterations), OverheadUs(h, l),
           absl::StrFormat("%.0f%%", 100.0 * l.solves_per_s / h.capacity_per_s));
}

void PrintPeerLevel(const char* label, const LevelReport& peer, double busy_ms) {
  PrintRow(label, peer, "-", (peer.p50_ms - busy_ms) * 1e3, "-");
}

void PrintRatios(const LevelReport& l) {
  std::printf("%5d ratios", l.config.concurrency);
  for (const auto& [label, peer] : {std::pair{"inline", l.inline_solve.get()}, std::pair{"bare", l.bare.get()}}) {
    if (peer == nullptr || peer->solves_per_s <= 0.0) continue;
    std::printf("  nupmpc/%s: solves/s %.1f%%, p50 %+.0f \xc2\xb5s, p99 %.2fx", label,
                100.0 * l.solves_per_s / peer->solves_per_s, (l.p50_ms - peer->p50_ms) * 1e3, l.p99_ms / peer->p99_ms);
  }
  if (l.inline_core.sessions > 0) {
    // The peer spins each state's median: a solve's mean is what a server pays.
    std::printf("  inline busy: core alone, %d sessions in turn, median %.4f ms, mean %.4f ms; spun per step %.4f ms",
                l.inline_core.sessions, l.inline_core.median_ms, l.inline_core.mean_ms, l.inline_core.busy_mean_ms);
  }
  std::printf("  streams served: least %.2f, most %.2f of the mean\n", l.stream_min_share, l.stream_max_share);
  std::fflush(stdout);
}

void PrintJson(const RunHeader& h, const std::vector<LevelReport>& levels) {
  nlohmann::json out;
  out["instance"] = h.instance;
  out["server"] = {{"target", h.target},
                   {"version", h.server.version()},
                   {"worker_threads", h.server.limits().worker_threads()},
                   {"solver_cores", h.server.limits().solver_cores()},
                   {"queue_capacity", h.server.limits().queue_capacity()},
                   {"cpus", h.server.cpus()},
                   {"inline_solve_max_ms", h.server.limits().inline_solve_max_ms()}};
  out["peer_cpus"] = h.peer_cpus;
  out["generator_cpus"] = h.generator_cpus;
  out["core_baseline"] = {{"median_ms", h.baseline.median_ms}, {"mean_ms", h.baseline.mean_ms},
                          {"p99_ms", h.baseline.p99_ms},       {"mean_iterations", h.baseline.mean_iterations},
                          {"solves", h.baseline.solves},       {"capacity_cores", h.solve_cores},
                          {"capacity_per_s", h.capacity_per_s}};
  out["transport"] = {{"p50_us", h.transport.p50_us}, {"p99_us", h.transport.p99_us}, {"calls", h.transport.calls}};
  out["levels"] = nlohmann::json::array();
  for (const LevelReport& l : levels) {
    nlohmann::json level = {{"concurrency", l.config.concurrency},
                            {"mode", l.config.closed_loop ? "closed" : "open"},
                            {"measured_s", l.measured_s},
                            {"sent", l.tally.sent},
                            {"solves", l.tally.latency_ms.size()},
                            {"solves_per_s", l.solves_per_s},
                            {"p50_ms", l.p50_ms},
                            {"p90_ms", l.p90_ms},
                            {"p99_ms", l.p99_ms},
                            {"p999_ms", l.p999_ms},
                            {"max_ms", l.max_ms},
                            {"service_p50_ms", l.service_p50_ms},
                            {"service_p99_ms", l.service_p99_ms},
                            {"server_solve_p50_ms", l.solve_p50_ms},
                            {"mean_iterations", l.mean_iterations},
                            {"superseded", l.tally.superseded},
                            {"no_plan", l.tally.no_plan},
                            {"errors", l.tally.errors},
                            {"overhead_p50_us", OverheadUs(h, l)},
                            {"fraction_of_capacity", l.solves_per_s / h.capacity_per_s},
                            {"stream_min_share", l.stream_min_share},
                            {"stream_max_share", l.stream_max_share},
                            {"starved_a_stream", StarvedAStream(l)}};
    if (!l.config.closed_loop) level["offered_per_s"] = l.config.rate_per_s;
    if (l.echo != nullptr) level["echo"] = PeerJson(*l.echo);
    if (l.inline_solve != nullptr) {
      level["inline"] = PeerJson(*l.inline_solve);
      level["inline"]["core_median_ms"] = l.inline_core.median_ms;
      level["inline"]["core_mean_ms"] = l.inline_core.mean_ms;
      level["inline"]["busy_mean_ms"] = l.inline_core.busy_mean_ms;
      level["inline"]["core_sessions_in_turn"] = l.inline_core.sessions;
      level["vs_inline"] = VersusPeerJson(l, *l.inline_solve);
    }
    if (l.bare != nullptr) {
      level["bare"] = PeerJson(*l.bare);
      level["vs_bare"] = VersusPeerJson(l, *l.bare);
    }
    out["levels"].push_back(std::move(level));
  }
  std::printf("%s\n", out.dump(2).c_str());
}

void PrintFleet(const RunHeader& h, const FleetReport& f, const LevelReport& separate,
                const FleetCoreBaseline& core_in_turn, bool json) {
  // A fleet call runs on the workers only: its capacities count them, not the solver cores.
  const double worker_capacity = h.fleet_cores / (h.baseline.median_ms * 1e-3);
  const double of_capacity = f.steps_per_s / worker_capacity;
  const double fleet_capacity = h.fleet_cores / (core_in_turn.mean_ms * 1e-3);
  const double of_fleet_capacity = f.steps_per_s / fleet_capacity;
  const double vs_streams = separate.solves_per_s > 0.0 ? f.steps_per_s / separate.solves_per_s : 0.0;
  if (json) {
    const nlohmann::json out = {{"instance", h.instance},
                                {"sessions", f.sessions},
                                {"calls_in_flight", f.calls_in_flight},
                                {"calls", f.calls},
                                {"fleet_steps_per_s", f.steps_per_s},
                                {"fleet_mean_iterations", f.mean_iterations},
                                {"call_p50_ms", f.call_p50_ms},
                                {"call_p99_ms", f.call_p99_ms},
                                {"step_errors", f.step_errors},
                                {"separate_streams_solves_per_s", separate.solves_per_s},
                                {"worker_cores", h.fleet_cores},
                                {"capacity_per_s", worker_capacity},
                                {"fraction_of_capacity", of_capacity},
                                {"core_in_turn_mean_ms", core_in_turn.mean_ms},
                                {"core_in_turn_mean_iterations", core_in_turn.mean_iterations},
                                {"core_in_turn_capacity_per_s", fleet_capacity},
                                {"fraction_of_core_in_turn_capacity", of_fleet_capacity},
                                {"vs_separate_streams", vs_streams}};
    std::printf("%s\n", out.dump(2).c_str());
    return;
  }
  const std::string calls = f.calls_in_flight == 1
                                ? "per SolveFleet call"
                                : absl::StrCat("in ", f.calls_in_flight, " SolveFleet calls in flight at once");
  std::printf(
      "fleet: %d sessions %s: %.0f steps/s (%.0f%% of capacity %d workers / median = "
      "%.0f/s), %.2f iterations/step, call p50 %.3f ms, p99 %.3f ms, %llu step errors\n",
      f.sessions, calls.c_str(), f.steps_per_s, 100.0 * of_capacity, h.fleet_cores, worker_capacity, f.mean_iterations,
      f.call_p50_ms, f.call_p99_ms, static_cast<unsigned long long>(f.step_errors));
  std::printf(
      "       the core alone stepping the %d sessions in turn (warm, as the fleet's calls after warm-up): "
      "mean %.4f ms per step, %.2f iterations/step, capacity %d workers / mean = %.0f steps/s; the fleet "
      "call reaches %.0f%% of it\n",
      f.sessions, core_in_turn.mean_ms, core_in_turn.mean_iterations, h.fleet_cores, fleet_capacity,
      100.0 * of_fleet_capacity);
  std::printf("       %d separate Control streams: %.0f solves/s, p50 %.3f ms; fleet / streams = %.2fx\n",
              separate.config.concurrency, separate.solves_per_s, separate.p50_ms, vs_streams);
  std::fflush(stdout);
}

void PrintIdleSessions(const std::string& instance, const IdleSessionsReport& r, bool json) {
  const auto per_session_kib = [&](std::uint64_t rss) {
    return r.sessions > 0 ? (static_cast<double>(rss) - static_cast<double>(r.rss_before)) / 1024.0 / r.sessions : 0.0;
  };
  if (json) {
    const nlohmann::json out = {{"instance", instance},
                                {"sessions", r.sessions},
                                {"rss_before_bytes", r.rss_before},
                                {"rss_with_sessions_bytes", r.rss_with_sessions},
                                {"rss_idle_bytes", r.rss_idle},
                                {"rss_after_bytes", r.rss_after},
                                {"per_session_kib", per_session_kib(r.rss_with_sessions)},
                                {"per_idle_session_kib", per_session_kib(r.rss_idle)},
                                {"compact_idle_s", r.compact_idle_s},
                                {"create_s", r.create_s},
                                {"release", r.expired ? "expire" : "close"},
                                {"release_s", r.release_s}};
    std::printf("%s\n", out.dump(2).c_str());
    return;
  }
  std::printf("nupmpc-loadtest: %d idle %s sessions\n", r.sessions, instance.c_str());
  std::printf("  server RSS before      %9.1f MiB\n", MiB(r.rss_before));
  std::printf("  with the sessions      %9.1f MiB  (%.1f KiB per session; created and solved once in %.2f s)\n",
              MiB(r.rss_with_sessions), per_session_kib(r.rss_with_sessions), r.create_s);
  std::printf("  idle (compacted after %.0f s) %5.1f MiB  (%.1f KiB per session)\n", r.compact_idle_s, MiB(r.rss_idle),
              per_session_kib(r.rss_idle));
  std::printf("  after they %s  %9.1f MiB  (%+.1f%% of before; released in %.2f s)\n",
              r.expired ? "expired" : "closed ", MiB(r.rss_after),
              r.rss_before > 0 ? 100.0 * (static_cast<double>(r.rss_after) / r.rss_before - 1.0) : 0.0, r.release_s);
}

}  // namespace nupmpc::loadtest
