// [KL] §V-C / Fig. 21: K = 300 with five double-slit walls. Flies eight random layouts,
// prints each one's slit violation and passes, and writes layout 1 as flappy_bird.csv
// (height and flaps) and flappy_walls.csv.
#include <cstdio>

#include "core/examples/csv_table.h"
#include "core/examples/example_command_line.h"
#include "core/examples/scenarios/flappy_bird.h"

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-example-flappy-bird",
    .summary =
        "nupmpc-example-flappy-bird: [KL] §V-C / Fig. 21, K = 300 with five double-slit walls. Flies "
        "eight random layouts, prints each one's slit violation and passes, and writes layout 1 into "
        "--out_dir as flappy_bird.csv (height and flaps) and flappy_walls.csv.",
    .usage = "nupmpc-example-flappy-bird [--out_dir DIR]",
    .max_arguments = 0,
};

}  // namespace

int main(int argc, char** argv) {
  namespace ex = nupmpc::examples;
  const std::string dir = ex::ParseExampleCommandLine(kProgram, argc, argv);
  constexpr int kSteps = 300, kLayouts = 8;
  int passed = 0;
  for (unsigned layout = 1; layout <= kLayouts; ++layout) {
    const std::vector<ex::Wall> walls = ex::RandomWalls(kSteps, 5, layout);
    auto run = ex::FlyThroughWalls(kSteps, walls, {});
    if (!run.ok()) {
      std::fprintf(stderr, "%s\n", run.status().ToString().c_str());
      return 1;
    }
    passed += run->worst_slit_violation == 0.0;
    std::printf(
        "flappy bird K=%d layout %u: worst slit violation %.3g, %0.f flaps, %d passes, gap before rounding %.3g, "
        "%d search moves, %.1f ms\n",
        kSteps, layout, run->worst_slit_violation, run->flaps.sum(), run->iterations, run->discrete_gap,
        run->discrete_moves, 1e3 * run->seconds);
    if (layout != 1) continue;
    Eigen::VectorXd first(walls.size()), width(walls.size()), low(walls.size()), separation(walls.size());
    for (std::size_t i = 0; i < walls.size(); ++i) {
      first(i) = walls[i].first_step;
      width(i) = walls[i].width;
      low(i) = walls[i].upper_low;
      separation(i) = walls[i].separation;
    }
    const bool ok =
        ex::WriteCsv(dir + "/flappy_bird.csv", {{"step", Eigen::VectorXd::LinSpaced(kSteps + 1, 0, kSteps)},
                                                {"height", run->height},
                                                {"flap", run->flaps}})
            .ok() &&
        ex::WriteCsv(dir + "/flappy_walls.csv",
                     {{"first_step", first}, {"width", width}, {"upper_low", low}, {"separation", separation}})
            .ok();
    if (!ok) return 1;
  }
  std::printf("flappy bird: %d of %d layouts pass every slit\n", passed, kLayouts);
  return 0;
}
