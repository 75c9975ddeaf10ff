// [KL] §V-B / Fig. 20: the five input versions on one corridor; writes corridor.csv and
// prints the corridor violation and each version's structural counts.
#include <cstdio>

#include "core/examples/csv_table.h"
#include "core/examples/example_command_line.h"
#include "core/examples/scenarios/corridor.h"

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-example-corridor",
    .summary =
        "nupmpc-example-corridor: [KL] §V-B / Fig. 20, the five input versions on one corridor. Prints "
        "the corridor violation and each version's structural counts and writes corridor.csv into "
        "--out_dir.",
    .usage = "nupmpc-example-corridor [--out_dir DIR]",
    .max_arguments = 0,
};

}  // namespace

int main(int argc, char** argv) {
  namespace ex = nupmpc::examples;
  const std::string dir = ex::ParseExampleCommandLine(kProgram, argc, argv);
  const int K = ex::kCorridorSteps;
  Eigen::VectorXd target(K + 1);
  for (int n = 0; n <= K; ++n) target(n) = ex::CorridorTarget(n);
  ex::CsvColumns columns = {{"step", Eigen::VectorXd::LinSpaced(K + 1, 0, K)}, {"target", target}};
  int failed = 0;
  for (int v = 1; v <= 5; ++v) {
    const auto version = static_cast<ex::CorridorVersion>(v);
    auto run = ex::RunCorridor(version);
    if (!run.ok()) {
      std::fprintf(stderr, "%s: %s\n", ex::CorridorVersionName(version), run.status().ToString().c_str());
      ++failed;
      continue;
    }
    std::printf(
        "%d %-15s corridor violation %.1e  nonzero u %3d  switches %3d  min Δu %+.4f  level gap %.2e  passes %4d  %.1f "
        "ms\n",
        v, ex::CorridorVersionName(version), run->max_corridor_violation, run->nonzero_inputs, run->input_switches,
        run->min_input_change, run->level_gap, run->iterations, 1e3 * run->seconds);
    columns.push_back({std::string("u_") + ex::CorridorVersionName(version), run->inputs});
    columns.push_back({std::string("y_") + ex::CorridorVersionName(version), run->outputs});
  }
  columns.push_back({"half_width", Eigen::VectorXd::Constant(1, ex::kCorridorHalfWidth)});
  return failed || !ex::WriteCsv(dir + "/corridor.csv", columns).ok();
}
