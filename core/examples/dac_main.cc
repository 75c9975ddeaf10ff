// [KL] §V-A, Figs. 2, 18, 19 (nup-algorithms.md §7): writes dac_long_2hz.csv and
// dac_long_40hz.csv (K = 450, one plan each, EM with a 2000-pass budget, rounded) and
// dac_online.csv (receding horizon 8: IAKE-EM vs exhaustive search, 300 steps); prints
// MSE, passes and times, and the long-horizon vs horizon-8 comparison of Fig. 18.
#include <cstdio>

#include "core/examples/csv_table.h"
#include "core/examples/scenarios/dac.h"

namespace {

using nupmpc::examples::CsvColumns;

Eigen::VectorXd Steps(Eigen::Index n, int first) { return Eigen::VectorXd::LinSpaced(n, first, first + n - 1); }

}  // namespace

int main(int argc, char** argv) {
  namespace ex = nupmpc::examples;
  const std::string dir = ex::OutputDirectory(argc, argv);
  constexpr int kLong = 450, kBudget = 2000, kWindow = 8, kSteps = 300;
  constexpr double kLongVariance = 0.045, kOnlineVariance = 0.01;
  // 2 Hz lies in the filter's passband, 40 Hz far outside it (the plant cannot follow:
  // the best a binary input can do is hold the mean).
  for (const double hz : {2.0, 40.0}) {
    auto plan = ex::DacLongPlan(kLong, kLongVariance, hz, kBudget, /*em=*/true);
    if (!plan.ok()) {
      std::fprintf(stderr, "%s\n", plan.status().ToString().c_str());
      return 1;
    }
    std::printf("long plan %4.0f Hz: K=%d EM, MSE %.3e after rounding, %d passes, gap before rounding %.3f, %.1f ms\n",
                hz, kLong, plan->mse, plan->iterations, plan->discrete_gap, 1e3 * plan->seconds);
    const absl::Status written = ex::WriteCsv(
        dir + "/dac_long_" + std::to_string(static_cast<int>(hz)) + "hz.csv",
        {{"step", Steps(kLong + 1, 0)}, {"target", plan->target}, {"output", plan->outputs}, {"input", plan->inputs}});
    if (!written.ok()) return 1;
  }
  auto online = ex::DacOnline(kWindow, kSteps, kOnlineVariance, 2.0, 300);
  if (!online.ok()) {
    std::fprintf(stderr, "%s\n", online.status().ToString().c_str());
    return 1;
  }
  std::printf("online K=%d, %d steps: MSE IAKE-EM %.4e vs exhaustive %.4e (ratio %.3f), %.3f ms per step\n", kWindow,
              kSteps, online->nup_mse, online->exhaustive_mse, online->nup_mse / online->exhaustive_mse,
              1e3 * online->nup_seconds / kSteps);
  // Fig. 18: one long plan over the same 300 steps against the horizon-8 controllers.
  auto long300 = ex::DacLongPlan(kSteps, kOnlineVariance, 2.0, kBudget, true);
  if (long300.ok()) {
    std::printf("Fig. 18: long plan K=%d MSE %.4e vs exhaustive K=%d online %.4e (ratio %.3f)\n", kSteps, long300->mse,
                kWindow, online->exhaustive_mse, long300->mse / online->exhaustive_mse);
  }
  const CsvColumns columns = {{"step", Steps(kSteps, 1)},
                              {"target", online->target},
                              {"nup_output", online->nup_outputs},
                              {"exhaustive_output", online->exhaustive_outputs},
                              {"nup_input", online->nup_inputs},
                              {"exhaustive_input", online->exhaustive_inputs}};
  return ex::WriteCsv(dir + "/dac_online.csv", columns).ok() ? 0 : 1;
}
