// nupmpc-gp-bench: [Nghiem] Table I on this machine. For each training-set size N, a GP
// model of the tanh plant drives two 100-step closed loops, one with linGP-SCP on the NUP
// core and one with Ipopt on the full GP-MPC NLP (same run, same noise); prints the time
// per MPC step (mean, std, median), the SCP's time in its NUP subproblems, the speed-up,
// tracking error and constraint satisfaction of both loops and the largest difference
// between the two solvers' plans on identical problems. --csv DIR writes the closed-loop
// trajectories for plot_gp.py.
//
//   nupmpc-gp-bench [--sizes 500,700,900,1100,1300,1500] [--steps 100] [--csv DIR] [--no_ipopt]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "cli/program_flags.h"
#include "core/examples/csv_table.h"
#include "core/examples/scenarios/gp_tanh.h"
#include "core/gp/hyperparameter_fit.h"
#include "loadtest/bench/gp/gp_closed_loop.h"

ABSL_FLAG(std::string, sizes, "500,700,900,1100,1300,1500", "training-set sizes N");
ABSL_FLAG(int, steps, 100, "closed-loop steps per run");
ABSL_FLAG(int, fit_points, 300, "points for the hyper-parameter fit (reused for every N)");
ABSL_FLAG(std::string, csv, "", "directory for closed-loop CSV files (empty: none)");
ABSL_FLAG(bool, no_ipopt, false, "skip the Ipopt loop");

namespace {

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-gp-bench",
    .summary =
        "nupmpc-gp-bench: [Nghiem] Table I on this machine. For each training-set size N, a GP model of "
        "the tanh plant drives two closed loops, one with linGP-SCP on the NUP core and one with Ipopt on "
        "the full GP-MPC NLP (same run, same noise); prints the time per MPC step (mean, std, median), "
        "the SCP's time in its NUP subproblems, the speed-up, tracking error and constraint satisfaction "
        "of both loops and the largest difference between the two solvers' plans. --csv DIR writes the "
        "closed-loop trajectories for plot_gp.py.",
    .usage = "nupmpc-gp-bench [--sizes 500,...,1500] [--steps 100] [--csv DIR] [--no_ipopt]",
    .max_arguments = 0,
};

struct Stats {
  double mean = 0.0, std = 0.0, median = 0.0;
};

Stats Summarise(std::vector<double> seconds) {
  Stats s;
  if (seconds.empty()) return s;
  for (double& v : seconds) v *= 1e3;
  s.mean = std::accumulate(seconds.begin(), seconds.end(), 0.0) / seconds.size();
  double var = 0.0;
  for (double v : seconds) var += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(var / seconds.size());
  std::nth_element(seconds.begin(), seconds.begin() + seconds.size() / 2, seconds.end());
  s.median = seconds[seconds.size() / 2];
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  std::vector<int> sizes;
  for (absl::string_view part : absl::StrSplit(absl::GetFlag(FLAGS_sizes), ',', absl::SkipEmpty())) {
    int n = 0;
    if (!absl::SimpleAtoi(part, &n) || n < 10) {
      return nupmpc::cli::ReportUsageError(kProgram, absl::StrCat("--sizes: bad size \"", part, "\" (at least 10)"));
    }
    sizes.push_back(n);
  }
  // Hyper-parameters: maximum likelihood on a few hundred points (O(N³) per evaluation),
  // then every model of size N uses them on its own data (seed 2, the first N points).
  absl::StatusOr<nupmpc::gp::NarxData> fit_data =
      nupmpc::examples::TanhTrainingData(absl::GetFlag(FLAGS_fit_points), /*seed=*/1);
  if (!fit_data.ok()) return 1;
  nupmpc::gp::SeArdKernel start;
  start.signal_variance = 1.0;
  start.length_scales = Eigen::Vector2d(1.0, 1.0);
  start.noise_variance = 0.01;
  absl::StatusOr<nupmpc::gp::FitResult> fit =
      nupmpc::gp::FitHyperparameters(fit_data->regressors, fit_data->targets, start);
  if (!fit.ok()) {
    std::fprintf(stderr, "fit: %s\n", fit.status().ToString().c_str());
    return 1;
  }
  std::printf(
      "hyper-parameters (ML on %d points, %d L-BFGS iterations, %.2f s): sf2 = %.4g, l = (%.4g, %.4g), sn2 = %.4g "
      "(noise std %.4f; true 0.025)\n",
      absl::GetFlag(FLAGS_fit_points), fit->iterations, fit->seconds, fit->kernel.signal_variance,
      fit->kernel.length_scales(0), fit->kernel.length_scales(1), fit->kernel.noise_variance,
      std::sqrt(fit->kernel.noise_variance));
  std::printf("\n%6s | %-26s | %-26s | %-26s | %7s | %-17s | %-17s | %9s %9s\n", "N", "linGP-SCP ms mean/std/med",
              "linGP-inner ms mean/std/med", "Ipopt ms mean/std/med", "speedup", "RMSE scp/ipopt", "max viol scp/ipopt",
              "max du", "J gap");
  const std::string csv_dir = absl::GetFlag(FLAGS_csv);
  for (int n : sizes) {
    absl::StatusOr<nupmpc::gp::NarxData> data = nupmpc::examples::TanhTrainingData(n, /*seed=*/2);
    if (!data.ok()) return 1;
    absl::StatusOr<nupmpc::gp::GpModel> model =
        nupmpc::gp::GpModel::Create(data->regressors, data->targets, fit->kernel);
    if (!model.ok()) {
      std::fprintf(stderr, "N=%d: %s\n", n, model.status().ToString().c_str());
      return 1;
    }
    nupmpc::bench::GpClosedLoopOptions options;
    options.steps = absl::GetFlag(FLAGS_steps);
    options.with_ipopt = !absl::GetFlag(FLAGS_no_ipopt);
    absl::StatusOr<nupmpc::bench::GpComparison> run =
        nupmpc::bench::RunGpClosedLoops(*model, nupmpc::examples::TanhMpcProblem(), options);
    if (!run.ok()) {
      std::fprintf(stderr, "N=%d: %s\n", n, run.status().ToString().c_str());
      return 1;
    }
    const Stats scp = Summarise(run->scp.step_seconds), inner = Summarise(run->scp.inner_seconds),
                ipopt = Summarise(run->ipopt.step_seconds);
    std::printf(
        "%6d | %8.3f %7.3f %8.3f | %8.3f %7.3f %8.3f | %8.2f %7.2f %8.2f | %6.1fx | %.4f / %.4f | %.1e / %.1e | %9.2e "
        "%9.2e\n",
        n, scp.mean, scp.std, scp.median, inner.mean, inner.std, inner.median, ipopt.mean, ipopt.std, ipopt.median,
        scp.median > 0 ? ipopt.median / scp.median : 0.0, run->scp.tracking_rmse, run->ipopt.tracking_rmse,
        run->scp.max_violation, run->ipopt.max_violation, run->max_plan_difference, run->max_objective_gap);
    if (run->scp.unconverged > 0 || run->ipopt.unconverged > 0) {
      std::printf("       (steps not converged: linGP-SCP %d, Ipopt %d)\n", run->scp.unconverged,
                  run->ipopt.unconverged);
    }
    if (!csv_dir.empty()) {
      const absl::Status written = nupmpc::examples::WriteCsv(
          csv_dir + "/gp_closed_loop_N" + std::to_string(n) + ".csv", {{"reference", run->scp.reference},
                                                                       {"y_scp", run->scp.y},
                                                                       {"u_scp", run->scp.u},
                                                                       {"y_ipopt", run->ipopt.y},
                                                                       {"u_ipopt", run->ipopt.u}});
      if (!written.ok()) std::fprintf(stderr, "%s\n", written.ToString().c_str());
    }
  }
  std::printf(
      "\nspeedup = Ipopt median / linGP-SCP median per MPC step; max du = largest ‖u_scp - u_ipopt‖∞ on the same "
      "step problem; J gap = largest relative excess of the SCP plan's exact cost over Ipopt's\n");
  return 0;
}
