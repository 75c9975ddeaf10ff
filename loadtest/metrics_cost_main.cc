// nupmpc-metrics-cost: what the server's metrics cost, measured in isolation: the
// recording a solve adds (Metrics::RecordSolve, on the worker, every solve) and one
// rendering of /metrics (once per scrape), with many sessions open. Their ratio to a solve
// and to a second bounds the metrics' share of the server's time; deploy/security-overhead.py
// measures the same end to end.
#include <chrono>
#include <cstdio>

#include "absl/flags/flag.h"
#include "cli/program_flags.h"
#include "client/problem_file.h"
#include "loadtest/core_baseline.h"
#include "server/metrics_exposition.h"
#include "server/sessions/session_factory.h"
#include "server/state/server_state.h"

ABSL_FLAG(std::string, instance, "benchmarks/masses_N30.json", "the sessions' problem");
ABSL_FLAG(int, sessions, 10000, "open sessions while /metrics is rendered");
ABSL_FLAG(int, records, 2000000, "RecordSolve calls timed");

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-metrics-cost",
    .summary = "nupmpc-metrics-cost: the cost of recording a solve's metrics and of rendering /metrics",
    .usage = "nupmpc-metrics-cost [--instance FILE] [--sessions N] [--records N]",
    .max_arguments = 0,
};

}  // namespace

int main(int argc, char** argv) {
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(absl::GetFlag(FLAGS_instance));
  if (!file.ok()) return nupmpc::cli::ReportUsageError(kProgram, file.status().message());
  if (file->closed_loop_states.empty()) {
    const auto& mean = file->spec.initial_state().mean();
    file->closed_loop_states.emplace_back(mean.begin(), mean.end());
  }
  absl::StatusOr<nupmpc::loadtest::CoreBaseline> baseline =
      nupmpc::loadtest::MeasureCoreBaseline(file->spec, file->closed_loop_states, 5);
  if (!baseline.ok()) return nupmpc::cli::ReportUsageError(kProgram, baseline.status().message());

  nupmpc::server::ServerOptions options;
  options.max_sessions = absl::GetFlag(FLAGS_sessions) + 1;
  nupmpc::server::ServerState state(options);
  nupmpc::v1::SolveResult result;
  result.set_status(nupmpc::v1::SOLVE_STATUS_CONVERGED);
  result.set_algorithm(nupmpc::v1::ALGORITHM_IFFBDD);
  result.set_iterations(4);
  result.set_solve_ms(baseline->median_ms);
  const int records = absl::GetFlag(FLAGS_records);
  const auto record_start = Clock::now();
  for (int i = 0; i < records; ++i) state.metrics.RecordSolve(result, 1e-5 * (i % 7), 1e-4 * (i % 13));
  const double record_ns = Seconds(Clock::now() - record_start) / records * 1e9;

  nupmpc::server::CallContext call;
  for (int i = 0; i < absl::GetFlag(FLAGS_sessions); ++i) {
    auto entry = nupmpc::server::CreateAndRegister(file->spec, options.size_limits, &state.gp_models, &state.budget,
                                                   &state.registry, call, false, {}, {});
    if (!entry.ok()) return nupmpc::cli::ReportUsageError(kProgram, entry.status().message());
  }
  constexpr int kRenders = 200;
  std::size_t bytes = 0;
  const auto render_start = Clock::now();
  for (int i = 0; i < kRenders; ++i) bytes = nupmpc::server::RenderPrometheusMetrics(state).size();
  const double render_us = Seconds(Clock::now() - render_start) / kRenders * 1e6;

  std::printf("core median closed-loop step (%s): %.1f us\n", absl::GetFlag(FLAGS_instance).c_str(),
              baseline->median_ms * 1e3);
  std::printf("RecordSolve: %.1f ns per solve = %.4f %% of a solve\n", record_ns,
              100.0 * record_ns * 1e-9 / (baseline->median_ms * 1e-3));
  std::printf(
      "/metrics with %d sessions: %.1f us per scrape (%zu bytes) = %.4f %% of one core at one scrape per "
      "second\n",
      absl::GetFlag(FLAGS_sessions), render_us, bytes, 100.0 * render_us * 1e-6);
  state.pool.Shutdown();
  return 0;
}
