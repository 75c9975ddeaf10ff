// nupmpc-bench: the core's speed and accuracy on benchmark instance files.
//
//   nupmpc-bench [--json] [--reference PATH] [--algorithm NAME] [--repeat R] [--scaling] [--trace] FILE...
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "cli/program_flags.h"
#include "core/public/session.h"
#include "loadtest/bench/bench_report.h"
#include "loadtest/instances/benchmark_instance.h"

ABSL_FLAG(bool, json, false, "print one JSON object per instance per line");
ABSL_FLAG(std::string, reference, "", "reference.json (default: the one beside each file)");
ABSL_FLAG(std::string, algorithm, "auto", "auto, iake, ibffd or iffbdd");
ABSL_FLAG(int, repeat, 5, "solves per instance; the median time is reported");
ABSL_FLAG(bool, scaling, false, "also report time per horizon step across the masses_N* files given");
ABSL_FLAG(bool, trace, false,
          "also print every pass of one cold solve per instance (region changes, objective, "
          "violation; polish residuals)");
ABSL_FLAG(int, max_iterations, 5000, "iteration cap per solve");
ABSL_FLAG(int, polish_after, 1, "polish once the active set is unchanged for this many iterations (0: never)");
ABSL_FLAG(int, polish_rounds, 4, "primal-dual active-set corrections after a failed polish");
ABSL_FLAG(bool, interior_point, true,
          "iterate cold IFFBDD solves of problems with hard output bounds only with the interior-point method "
          "(false: IFFBDD's dual NUP updates)");

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-bench",
    .summary =
        "nupmpc-bench: the core's speed and accuracy on benchmark instance files (format: "
        "benchmarks/README.md), in process, without the service. Per instance: algorithm, "
        "iterations, median cold solve time of --repeat solves, objective, relative gap to reference.json, "
        "max violation, status and GFLOP/s next to the machine's Eigen GEMM rate; instances with a "
        "closed loop also get warm and cold per-step times and iterations.",
    .usage = "nupmpc-bench [--json] [--reference PATH] [--algorithm NAME] [--repeat R] [--scaling] [--trace] FILE...",
};

int main(int argc, char** argv) {
  std::vector<char*> files = nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  files.erase(files.begin());
  if (files.empty()) return nupmpc::cli::ReportUsageError(kProgram, "no instance files given");
  nupmpc::bench::BenchOptions options;
  options.json = absl::GetFlag(FLAGS_json);
  options.reference = absl::GetFlag(FLAGS_reference);
  options.repeat = std::max(1, absl::GetFlag(FLAGS_repeat));
  options.max_iterations = absl::GetFlag(FLAGS_max_iterations);
  options.scaling = absl::GetFlag(FLAGS_scaling);
  options.trace = absl::GetFlag(FLAGS_trace);
  options.polish_after = absl::GetFlag(FLAGS_polish_after);
  options.polish_rounds = absl::GetFlag(FLAGS_polish_rounds);
  options.interior_point = absl::GetFlag(FLAGS_interior_point);
  absl::StatusOr<nupmpc::core::Algorithm> algorithm = nupmpc::core::ParseAlgorithm(absl::GetFlag(FLAGS_algorithm));
  if (!algorithm.ok()) return nupmpc::cli::ReportUsageError(kProgram, absl::StrCat("--", algorithm.status().message()));
  options.algorithm = *algorithm;
  std::vector<std::string> paths(files.begin(), files.end());
  return nupmpc::bench::RunBenchmarks(paths, options);
}
