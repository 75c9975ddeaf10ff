// nupmpc-api-example-bicycle: a kinematic bicycle follows a curved path past obstacles in
// closed loop through a running nupmpc-server (real-time iteration with NonlinearSession,
// client/examples/bicycle.h). Prints one line per period (linearisations, passes, times,
// the car's state), then the same run solved cold every period, and the comparison.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "absl/flags/flag.h"
#include "absl/strings/str_format.h"
#include "cli/program_flags.h"
#include "client/client.h"
#include "client/examples/bicycle.h"
#include "client/examples/period_table.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "server address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(int, periods, 200, "most control periods to run (the run ends earlier at the goal)");
ABSL_FLAG(bool, finite_differences, false, "linearise with finite differences instead of the analytic Jacobians");

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-api-example-bicycle",
    .summary =
        "nupmpc-api-example-bicycle: a kinematic bicycle follows a curved path past three obstacles in "
        "closed loop through a running nupmpc-server: each period the client linearises the car along the "
        "previous plan (NonlinearSession, real-time iteration) and the server plans with the obstacles as "
        "keep-out regions. Prints per period the linearisations, passes and times, then runs the same loop "
        "solved cold every period and compares passes and time per period.",
    .usage = "nupmpc-api-example-bicycle [--server HOST:PORT] [--periods P] [--finite_differences]",
    .environment = {{"NUPMPC_SERVER", "server address when --server is not given"}},
    .max_arguments = 0,
};

// The first periods of the warm run are left out of its means: the first is cold, the next
// few still settle from the standing start.
constexpr int kSettlePeriods = 5;

}  // namespace

int main(int argc, char** argv) {
  namespace ex = nupmpc::api_examples;
  if (const char* env = std::getenv("NUPMPC_SERVER"); env != nullptr) absl::SetFlag(&FLAGS_server, env);
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  if (absl::GetFlag(FLAGS_periods) < 1) return nupmpc::cli::ReportUsageError(kProgram, "--periods: must be at least 1");
  ex::BicycleScenario scenario;
  scenario.max_periods = absl::GetFlag(FLAGS_periods);
  const bool analytic = !absl::GetFlag(FLAGS_finite_differences);
  nupmpc::Client client(absl::GetFlag(FLAGS_server));

  nupmpc::NonlinearSessionOptions warm;  // RTI: one linearisation per period, shifted warm start
  std::printf("warm-started real-time iteration (%s Jacobians):\n", analytic ? "analytic" : "finite-difference");
  ex::PrintPeriodHeader(stdout);
  const auto print = [](const ex::BicyclePeriod& p) {
    ex::PrintPeriod(stdout, p.period, p.report,
                    absl::StrFormat("px=%6.2f py=%5.2f v=%4.2f e=%6.3f clear=%5.2f a=%5.2f steer=%6.3f %s", p.state[0],
                                    p.state[1], p.state[3], p.lateral_error, p.clearance, p.input[0], p.input[1],
                                    p.status == nupmpc::v1::SOLVE_STATUS_CONVERGED
                                        ? ""
                                        : nupmpc::v1::SolveStatus_Name(p.status).substr(13).c_str()));
  };
  absl::StatusOr<ex::BicycleRun> run = ex::RunBicycle(client, scenario, warm, analytic, print);
  if (!run.ok()) {
    std::fprintf(stderr, "nupmpc-api-example-bicycle: %s\n", run.status().ToString().c_str());
    return 1;
  }
  nupmpc::NonlinearSessionOptions cold = warm;
  cold.warm_start = nupmpc::v1::WARM_START_COLD;
  absl::StatusOr<ex::BicycleRun> cold_run = ex::RunBicycle(client, scenario, cold, analytic);
  if (!cold_run.ok()) {
    std::fprintf(stderr, "nupmpc-api-example-bicycle: cold run: %s\n", cold_run.status().ToString().c_str());
    return 1;
  }

  double min_clearance = 1e300, min_plan_clearance = 1e300, max_speed = 0, max_steer = 0, max_violation = 0;
  double min_a = 1e300, max_a = -1e300;
  std::vector<nupmpc::PeriodReport> reports, cold_reports;
  for (const ex::BicyclePeriod& p : run->periods) {
    min_clearance = std::min(min_clearance, p.clearance);
    min_plan_clearance = std::min(min_plan_clearance, p.plan_clearance);
    max_speed = std::max(max_speed, p.state[3]);
    max_steer = std::max(max_steer, std::abs(p.input[1]));
    min_a = std::min(min_a, p.input[0]);
    max_a = std::max(max_a, p.input[0]);
    max_violation = std::max(max_violation, p.max_violation);
    reports.push_back(p.report);
  }
  for (const ex::BicyclePeriod& p : cold_run->periods) cold_reports.push_back(p.report);
  const std::vector<double>& x = run->final_state;
  std::printf(
      "\n%s after %zu periods: px=%.2f, lateral error %.4f m, speed %.3f m/s (limit %.1f, max %.4f); least clearance "
      "%.3f m (car), %.3f m (plans; margin %.1f); |steer| <= %.4f (bound %.2f); a in [%.3f, %.3f] (bounds [%.1f, "
      "%.1f]); largest plan violation %.1e\n",
      run->reached_goal ? "goal reached" : "goal NOT reached", run->periods.size(), x[0],
      x[1] - ex::PathY(scenario, x[0]), x[3], scenario.speed_limit, max_speed, min_clearance, min_plan_clearance,
      scenario.margin, max_steer, scenario.max_steering, min_a, max_a, scenario.min_acceleration,
      scenario.max_acceleration, max_violation);
  ex::PrintWarmVsCold(stdout, ex::Summarise(reports, kSettlePeriods), ex::Summarise(cold_reports, kSettlePeriods));
  return 0;
}
