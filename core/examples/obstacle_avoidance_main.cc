// [KL] §V-D / Fig. 23: writes obstacles_single.csv, obstacles_mixed.csv and the regions
// (obstacles_regions.csv), prints clearance, goal error, linearisations and time.
#include <cstdio>
#include <numbers>

#include "core/examples/csv_table.h"
#include "core/examples/example_command_line.h"
#include "core/examples/scenarios/obstacle_avoidance.h"

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-example-obstacle-avoidance",
    .summary =
        "nupmpc-example-obstacle-avoidance: [KL] §V-D / Fig. 23, planning around keep-out regions (one "
        "circle; mixed shapes). Prints clearance, goal error, linearisations and time, and writes "
        "obstacles_single.csv, obstacles_mixed.csv and obstacles_regions.csv into --out_dir.",
    .usage = "nupmpc-example-obstacle-avoidance [--out_dir DIR]",
    .max_arguments = 0,
};

using nupmpc::core::KeepOutRegion;
using nupmpc::core::KeepOutShape;

int Run(const std::string& dir, const char* name, const std::vector<KeepOutRegion>& regions) {
  constexpr int kHorizon = 30;
  auto run = nupmpc::examples::PlanAroundObstacles(kHorizon, regions);
  if (!run.ok()) {
    std::fprintf(stderr, "%s: %s\n", name, run.status().ToString().c_str());
    return 1;
  }
  std::printf("%-16s converged=%d linearisations=%d passes=%d min_clearance=%.2e goal_error=%.1e time=%.2f ms\n", name,
              run->summary.converged, run->summary.linearisations, run->summary.inner_iterations, run->min_clearance,
              run->goal_error, 1e3 * run->summary.solve_seconds);
  const absl::Status written = nupmpc::examples::WriteCsv(
      dir + "/obstacles_" + name + ".csv", {{"p1", run->positions.col(0)}, {"p2", run->positions.col(1)}});
  if (!written.ok()) {
    std::fprintf(stderr, "%s\n", written.ToString().c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string dir = nupmpc::examples::ParseExampleCommandLine(kProgram, argc, argv);
  const auto single = nupmpc::examples::SingleCircleScene(5.0);  // the paper's γ = 5
  const auto mixed = nupmpc::examples::MixedShapesScene(nupmpc::core::kInfinity);
  const int failed = Run(dir, "single", single) + Run(dir, "mixed", mixed);
  // Regions for the plot: scene, shape (0 ellipse, 1 rectangle), centre, half-axes, rotation.
  Eigen::VectorXd scene(single.size() + mixed.size()), shape(scene.size()), c1(scene.size()), c2(scene.size()),
      a(scene.size()), b(scene.size()), rotation(scene.size());
  int i = 0;
  for (const auto* regions : {&single, &mixed}) {
    for (const KeepOutRegion& r : *regions) {
      scene(i) = regions == &single ? 0 : 1;
      shape(i) = r.shape == KeepOutShape::kRectangle;
      c1(i) = r.centre(0);
      c2(i) = r.centre(1);
      a(i) = r.half_axes(0);
      b(i) = r.half_axes(1);
      rotation(i) = r.rotation;
      ++i;
    }
  }
  const absl::Status written = nupmpc::examples::WriteCsv(
      dir + "/obstacles_regions.csv",
      {{"scene", scene}, {"shape", shape}, {"c1", c1}, {"c2", c2}, {"a", a}, {"b", b}, {"rotation", rotation}});
  return failed || !written.ok();
}
