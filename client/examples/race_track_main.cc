// nupmpc-api-example-race-track: the minimal-time lap of [KL] §V-E solved through a
// running nupmpc-server: the client linearises the vehicle (NonlinearSession, SQP with the
// core example's trust region and step control), the server solves each linearised
// problem warm from the one before. Prints lap time, bound violation, linearisations,
// passes and the time per linearisation; the core-only program is nupmpc-example-race-track.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "cli/program_flags.h"
#include "client/client.h"
#include "client/examples/period_table.h"
#include "client/examples/race_track.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "server address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(int, steps, 100, "spatial steps K of the lap (at least 20)");
ABSL_FLAG(int, max_linearisations, 300, "most linearisations (server solves) for the lap");

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-api-example-race-track",
    .summary =
        "nupmpc-api-example-race-track: [KL] §V-E, one minimal-time lap of the demo track through a running "
        "nupmpc-server: the client linearises the vehicle's spatial model along each plan and sends it as a "
        "time-varying model (NonlinearSession, SQP), the server solves. Prints lap time, bound violation, "
        "linearisations, passes (the first, cold solve against the warm ones after it) and time per "
        "linearisation. nupmpc-example-race-track solves the same lap in the core alone.",
    .usage = "nupmpc-api-example-race-track [--server HOST:PORT] [--steps K] [--max_linearisations L]",
    .environment = {{"NUPMPC_SERVER", "server address when --server is not given"}},
    .max_arguments = 0,
};

}  // namespace

int main(int argc, char** argv) {
  namespace ex = nupmpc::api_examples;
  if (const char* env = std::getenv("NUPMPC_SERVER"); env != nullptr) absl::SetFlag(&FLAGS_server, env);
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  const int steps = absl::GetFlag(FLAGS_steps);
  if (steps < 20) {
    return nupmpc::cli::ReportUsageError(kProgram, absl::StrCat("--steps ", steps, ": must be at least 20"));
  }
  ex::RaceSettings settings;
  settings.max_linearisations = absl::GetFlag(FLAGS_max_linearisations);
  if (settings.max_linearisations < 1) {
    return nupmpc::cli::ReportUsageError(kProgram, "--max_linearisations: must be at least 1");
  }
  nupmpc::Client client(absl::GetFlag(FLAGS_server));
  const ex::Track track = ex::DemoTrack();
  absl::StatusOr<ex::RaceLapRun> run = ex::RunRaceLap(client, track, ex::Vehicle{}, steps, settings);
  if (!run.ok()) {
    std::fprintf(stderr, "nupmpc-api-example-race-track: %s\n", run.status().ToString().c_str());
    return 1;
  }
  const nupmpc::PeriodReport& r = run->report;
  ex::PrintPeriodHeader(stdout);
  ex::PrintPeriod(stdout, 0, r, "(the whole lap is one period)");
  // The first solve starts cold on the centre-line guess; every later one continues from
  // the solve before it (WARM_START_KEEP) on a model that moved by one linearisation, but
  // along the race line, where the bounds are active: harder problems than the first.
  const std::vector<int>& passes = r.solve_passes;
  const double warm =
      passes.size() > 1 ? std::accumulate(passes.begin() + 1, passes.end(), 0.0) / (passes.size() - 1) : 0.0;
  std::printf(
      "race track K=%d length=%.3f: lap=%.4f s converged=%d linearisations=%d (rejected %d) passes=%d "
      "max_output_violation=%.1e model_defect=%.1e last_step=%.1e time=%.3f s (%.2f ms per linearisation: "
      "client %.2f, solver %.2f)\n",
      steps, track.length(), run->lap_time, r.converged, r.linearisations, r.rejected, r.passes,
      run->max_output_violation, r.model_defect, r.last_step, r.period_ms / 1000, r.period_ms / r.linearisations,
      r.linearise_ms / r.linearisations, r.solve_ms / r.linearisations);
  std::printf("passes: first (cold) solve %d, later (warm) solves %.1f on average\n", passes.empty() ? 0 : passes[0],
              warm);
  return 0;
}
