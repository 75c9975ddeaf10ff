// nupmpc-period-groups: groups of Control streams, each at its own control period, against
// a running server; prints one JSON object with, per group, the steps that got a plan by
// their deadline and those that did not, by cause (loadtest/period_groups.h). Driven by
// deploy/deadline-sweep.py, which starts FIFO and EDF servers and sets the load.
//
//   nupmpc-period-groups --server HOST:PORT
//       --group short:benchmarks/masses_N30.json:32:10,long:benchmarks/masses_N300.json:8:50 [--seconds 5]
//   nupmpc-period-groups --server HOST:PORT --group ... --calibrate_s 2
#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "cli/program_flags.h"
#include "client/problem_file.h"
#include "loadtest/period_groups.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "server address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(std::vector<std::string>, group, {},
          "the groups of streams, comma-separated, each NAME:INSTANCE:STREAMS:PERIOD_MS");
ABSL_FLAG(double, seconds, 5.0, "how long the groups run, counted");
ABSL_FLAG(double, warmup_s, 1.0, "before the counted time: sessions warm, not counted");
ABSL_FLAG(double, calibrate_s, 0.0,
          "> 0: instead, step each group's streams as fast as answers come for this long and print each group's "
          "steps per second (the server's capacity for that instance)");

namespace {

namespace lt = nupmpc::loadtest;

// User and system CPU time of this process so far.
double ProcessCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-period-groups",
    .summary =
        "nupmpc-period-groups: groups of Control streams at their control periods (the client library's period "
        "option), paced, against a running server; one JSON object: per group the steps, those with a plan by "
        "their deadline (met), those without by cause (queued past the deadline, a solve too long, held by the "
        "client, other), slack percentiles and how evenly the group's streams were served.",
    .usage = "nupmpc-period-groups --server HOST:PORT --group NAME:INSTANCE:STREAMS:PERIOD_MS[,...] [--seconds S]",
    .environment = {{"NUPMPC_SERVER", "address when --server is not given"}},
    .max_arguments = 0,
};

int Fail(const std::string& what, const absl::Status& s) {
  std::fprintf(stderr, "nupmpc-period-groups: %s: %s\n", what.c_str(), s.ToString().c_str());
  return 1;
}

absl::StatusOr<lt::PeriodGroup> ParseGroup(const std::string& text) {
  const std::vector<std::string> parts = absl::StrSplit(text, ':');
  int streams = 0;
  double period_ms = 0.0;
  if (parts.size() != 4 || !absl::SimpleAtoi(parts[2], &streams) || streams < 1 ||
      !absl::SimpleAtod(parts[3], &period_ms) || !(period_ms > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--group ", text, ": expected NAME:INSTANCE:STREAMS:PERIOD_MS with STREAMS >= 1, PERIOD_MS > 0"));
  }
  absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(parts[1]);
  if (!file.ok()) return file.status();
  lt::PeriodGroup group;
  group.name = parts[0];
  group.spec = file->spec;
  group.states = file->closed_loop_states;
  if (group.states.empty())
    group.states.emplace_back(file->spec.initial_state().mean().begin(), file->spec.initial_state().mean().end());
  group.streams = streams;
  group.period = std::chrono::microseconds(static_cast<long>(period_ms * 1e3));
  return group;
}

}  // namespace

int main(int argc, char** argv) {
  if (const char* env = std::getenv("NUPMPC_SERVER"); env != nullptr) absl::SetFlag(&FLAGS_server, env);
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  std::vector<lt::PeriodGroup> groups;
  for (const std::string& text : absl::GetFlag(FLAGS_group)) {
    absl::StatusOr<lt::PeriodGroup> group = ParseGroup(text);
    if (!group.ok()) return Fail("--group", group.status());
    groups.push_back(*std::move(group));
  }
  if (groups.empty()) return Fail("--group", absl::InvalidArgumentError("at least one group is needed"));
  const std::string server = absl::GetFlag(FLAGS_server);
  const auto ms = [](double s) { return std::chrono::milliseconds(static_cast<long>(s * 1e3)); };
  if (const double calibrate_s = absl::GetFlag(FLAGS_calibrate_s); calibrate_s > 0.0) {
    std::vector<std::string> parts;
    for (const lt::PeriodGroup& group : groups) {
      // As many streams as the group has: the capacity at that concurrency.
      absl::StatusOr<double> rate = lt::CalibrateStepsPerSecond(server, group, ms(calibrate_s), group.streams);
      if (!rate.ok()) return Fail("calibrating " + group.name, rate.status());
      parts.push_back(absl::StrCat("\"", group.name, "\":", *rate));
    }
    std::printf("{\"steps_per_s\":{%s}}\n", absl::StrJoin(parts, ",").c_str());
    return 0;
  }
  // This process's CPU time over the run's wall time: near 1 per CPU it may use, the
  // streams' own side (not the server) set the pace, and held steps are partly its own.
  const double cpu_before_s = ProcessCpuSeconds();
  const auto started = std::chrono::steady_clock::now();
  absl::StatusOr<std::vector<lt::GroupFigures>> figures =
      lt::RunPeriodGroups(server, groups, ms(absl::GetFlag(FLAGS_seconds)), ms(absl::GetFlag(FLAGS_warmup_s)));
  if (!figures.ok()) return Fail("running the groups", figures.status());
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::vector<std::string> lines;
  for (const lt::GroupFigures& f : *figures) lines.push_back(lt::GroupFiguresJson(f));
  std::printf("{\"groups\":[%s],\"client_cpu_share\":%.3f}\n", absl::StrJoin(lines, ",").c_str(),
              (ProcessCpuSeconds() - cpu_before_s) / wall_s);
  return 0;
}
