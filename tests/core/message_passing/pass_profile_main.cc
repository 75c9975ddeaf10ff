// Where the time of one large solve goes (a SolveOnce with M = 300, L = 30, K = 300,
// N = 200 and a 1 s deadline must not hold a worker long past its deadline), and how
// long a solve with a time limit takes. Not a test; run by hand:
//
//   pass_profile M L K N algorithm(iffbdd|ibffd|iake) time_limit_seconds
//   pass_profile overhead M L K N algorithm
//
// Prints the time of problem generation, Session::Create, each of the first passes of an
// unlimited solve (one Solve per pass, warm), the final evaluation, and a cold solve
// with the time limit (how far past the limit it returned).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "core/session/footprint.h"
#include "core/session/session.h"
#include "tests/util/random_problem.h"

namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

}  // namespace

// The cost of armed limits on a small problem: the same 10-pass solves with and without a
// time limit and cancel flag (the polls then read the clock at most once per pass).
int Overhead(int argc, char** argv) {
  using namespace nupmpc;
  testing::RandomProblemSpec spec;
  spec.M = std::atoi(argv[2]);
  spec.L = std::atoi(argv[3]);
  spec.K = std::atoi(argv[4]);
  spec.N = std::atoi(argv[5]);
  const std::string algorithm = argc > 6 ? argv[6] : "iffbdd";
  core::Problem p = testing::WithBoxes(testing::RandomGaussianProblem(spec), 0.5, algorithm == "ibffd" ? 0.0 : 2.0);
  core::SolverOptions options;
  options.algorithm = algorithm == "iake"    ? core::Algorithm::kIake
                      : algorithm == "ibffd" ? core::Algorithm::kIbffd
                                             : core::Algorithm::kIffbdd;
  options.polish_after_stable_iterations = 0;
  options.objective_tolerance = 1e-300;
  options.violation_tolerance = 1e-300;
  auto session = core::Session::Create(p, options);
  if (!session.ok()) return 1;
  std::atomic<bool> cancel{false};
  core::SolveLimits plain, armed;
  plain.max_iterations = armed.max_iterations = 10;
  plain.warm_start = armed.warm_start = false;
  armed.time_limit_seconds = 1e6;
  armed.cancel = &cancel;
  const int solves = std::max(1, static_cast<int>(2e8 / core::EstimateFootprint(core::ShapeOf(p)).flops_per_pass));
  double best_plain = 1e300, best_armed = 1e300;
  for (int rep = 0; rep < 7; ++rep) {
    for (const bool with_limits : {false, true}) {
      const auto t = Clock::now();
      for (int i = 0; i < solves; ++i) (void)(*session)->Solve(with_limits ? armed : plain, nullptr);
      double& best = with_limits ? best_armed : best_plain;
      best = std::min(best, Since(t) / solves);
    }
  }
  std::printf("%s M=%d L=%d K=%d N=%d: 10-pass solve %.2f us without limits, %.2f us with (%+.2f %%)\n",
              algorithm.c_str(), spec.M, spec.L, spec.K, spec.N, best_plain * 1e6, best_armed * 1e6,
              100.0 * (best_armed / best_plain - 1.0));
  return 0;
}

int main(int argc, char** argv) {
  using namespace nupmpc;
  if (argc > 1 && std::string(argv[1]) == "overhead" && argc > 5) return Overhead(argc, argv);
  if (argc < 7) {
    std::fprintf(stderr, "usage: pass_profile M L K N iffbdd|ibffd|iake time_limit_seconds [passes]\n");
    return 2;
  }
  testing::RandomProblemSpec spec;
  spec.M = std::atoi(argv[1]);
  spec.L = std::atoi(argv[2]);
  spec.K = std::atoi(argv[3]);
  spec.N = std::atoi(argv[4]);
  spec.time_varying = false;
  const std::string algorithm = argv[5];
  const double time_limit = std::atof(argv[6]);
  const int passes = argc > 7 ? std::atoi(argv[7]) : 3;

  auto t = Clock::now();
  core::Problem p = testing::RandomGaussianProblem(spec);
  p = testing::WithBoxes(std::move(p), 0.5, algorithm == "ibffd" ? 0.0 : 2.0);
  core::SolverOptions options;
  options.algorithm = algorithm == "iake"    ? core::Algorithm::kIake
                      : algorithm == "ibffd" ? core::Algorithm::kIbffd
                                             : core::Algorithm::kIffbdd;
  std::printf("problem generated: %.3f s\n", Since(t));
  const core::Footprint f = core::EstimateFootprint(core::ShapeOf(p));
  std::printf("estimate: %.1f MB, %.3g flops/step, %.3g flops/pass\n", f.total_bytes() / 1e6, f.flops_per_step,
              f.flops_per_pass);

  t = Clock::now();
  auto session = core::Session::Create(p, options);
  if (!session.ok()) {
    std::fprintf(stderr, "%s\n", session.status().ToString().c_str());
    return 1;
  }
  std::printf("Session::Create: %.3f s (%s)\n", Since(t), core::AlgorithmName((*session)->algorithm()));

  core::Solution solution;
  for (int i = 0; i < passes; ++i) {
    core::SolveLimits one;
    one.max_iterations = 1;
    one.warm_start = i > 0;
    t = Clock::now();
    auto s = (*session)->Solve(one, nullptr);
    std::printf("pass %d (one-pass Solve, no Solution): %.3f s  %s\n", i + 1, Since(t), s->Describe().c_str());
  }
  t = Clock::now();
  {
    core::SolveLimits one;
    one.max_iterations = 1;
    auto s = (*session)->Solve(one, &solution);
    std::printf("one more pass + Solution copy: %.3f s\n", Since(t));
  }
  if (time_limit > 0.0) {
    core::SolveLimits limited;
    limited.time_limit_seconds = time_limit;
    limited.warm_start = false;
    t = Clock::now();
    auto s = (*session)->Solve(limited, &solution);
    const double took = Since(t);
    std::printf("cold Solve with a %.3f s limit: returned after %.3f s (%.3f s past the limit): %s, has_plan %d\n",
                time_limit, took, took - time_limit, s->Describe().c_str(), s->has_plan ? 1 : 0);
    t = Clock::now();
    auto full = (*session)->Solve(core::SolveLimits{}, nullptr);
    std::printf("next Solve without limit: %.3f s: %s\n", Since(t), full->Describe().c_str());
  }
  return 0;
}
