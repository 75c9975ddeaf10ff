// [KL] §V-E / Fig. 25: one minimal-time lap of the demo track (K = 1000 spatial steps by
// default, or --steps); writes race_track.csv (the race line and the track's edges in the
// plane, the speed and the constrained outputs along s) and prints lap time,
// linearisations, passes, constraint and model errors, the centre-line reference lap
// and the solve time.
#include <cstdio>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "core/examples/csv_table.h"
#include "core/examples/example_command_line.h"
#include "core/examples/scenarios/race_track.h"

ABSL_FLAG(int, steps, 1000, "spatial steps K of the lap (at least 20)");

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-example-race-track",
    .summary =
        "nupmpc-example-race-track: [KL] §V-E / Fig. 25, one minimal-time lap of the demo track. Writes "
        "race_track.csv into --out_dir (the race line and the track's edges in the plane, the speed and "
        "the constrained outputs along s) and prints lap time, linearisations, passes, constraint and "
        "model errors, the centre-line reference lap and the solve time.",
    .usage = "nupmpc-example-race-track [--out_dir DIR] [--steps K]",
    .max_arguments = 0,
};

}  // namespace

int main(int argc, char** argv) {
  const std::string dir = nupmpc::examples::ParseExampleCommandLine(kProgram, argc, argv, [] {
    const int steps = absl::GetFlag(FLAGS_steps);
    return steps < 20 ? absl::StrCat("--steps ", steps, ": must be at least 20") : std::string();
  });
  const int steps = absl::GetFlag(FLAGS_steps);
  const nupmpc::examples::Track track = nupmpc::examples::DemoTrack();
  const nupmpc::examples::Vehicle vehicle;
  const nupmpc::examples::RaceSettings settings;
  auto run = nupmpc::examples::RaceLap(track, vehicle, steps, settings);
  if (!run.ok()) {
    std::fprintf(stderr, "race track: %s\n", run.status().ToString().c_str());
    return 1;
  }
  const double centre_line = nupmpc::examples::CentreLineLapTime(track, vehicle, settings.start_speed, 100 * steps);
  const auto& summary = run->summary;
  std::printf(
      "race track K=%d length=%.3f: lap=%.4f s (centre-line point mass %.4f s) converged=%d linearisations=%d "
      "(rejected %d) passes=%d max_output_violation=%.1e model_defect=%.1e last_step=%.1e time=%.2f s\n",
      steps, track.length(), run->lap_time, centre_line, summary.converged, summary.linearisations, summary.rejected,
      summary.inner_iterations, run->max_output_violation, run->model_defect, summary.last_step, summary.solve_seconds);
  const Eigen::MatrixXd& x = run->plan.states;
  const int rows = steps + 1;
  Eigen::VectorXd s(rows), px(rows), py(rows), lx(rows), ly(rows), rx(rows), ry(rows), a_total(rows);
  const nupmpc::core::NonlinearModel model = nupmpc::examples::RaceModel(track, vehicle, steps);
  Eigen::VectorXd y(4);
  Eigen::MatrixXd C(4, 6);
  for (int n = 0; n <= steps; ++n) {
    s(n) = n * track.length() / steps;
    const Eigen::Vector2d on_line = track.point(s(n), x(n, 0));
    const Eigen::Vector2d left = track.point(s(n), nupmpc::examples::kTrackHalfWidth);
    const Eigen::Vector2d right = track.point(s(n), -nupmpc::examples::kTrackHalfWidth);
    px(n) = on_line(0);
    py(n) = on_line(1);
    lx(n) = left(0);
    ly(n) = left(1);
    rx(n) = right(0);
    ry(n) = right(1);
    model.output(n, x.row(n).transpose(), &y, &C);
    a_total(n) = nupmpc::examples::TotalAccelerationSquared(y);
  }
  const absl::Status written = nupmpc::examples::WriteCsv(dir + "/race_track.csv", {{"s", s},
                                                                                    {"x", px},
                                                                                    {"y", py},
                                                                                    {"left_x", lx},
                                                                                    {"left_y", ly},
                                                                                    {"right_x", rx},
                                                                                    {"right_y", ry},
                                                                                    {"z", x.col(0)},
                                                                                    {"speed", x.col(2)},
                                                                                    {"a", x.col(3)},
                                                                                    {"delta", x.col(4)},
                                                                                    {"t", x.col(5)},
                                                                                    {"a_total_sq", a_total}});
  if (!written.ok()) {
    std::fprintf(stderr, "%s\n", written.ToString().c_str());
    return 1;
  }
  return 0;
}
