#include "core/examples/scenarios/gp_tanh.h"

#include <algorithm>
#include <cmath>
#include <random>

namespace nupmpc::examples {

double TanhPlantStep(double x, double u) { return x - 0.5 * std::tanh(x + u * u * u); }

TanhExperiment RunTanhExperiment(int samples, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> step(-0.5, 0.5);
  std::normal_distribution<double> noise(0.0, kTanhNoiseStd);
  TanhExperiment e{Eigen::VectorXd(samples), Eigen::VectorXd(samples)};
  double x = 0.0, u = 0.0;
  for (int k = 0; k < samples; ++k) {
    // u[k] acts between samples k-1 and k ([Nghiem] (21a): ȳ[k] = μ(ȳ[k-1], u[k])).
    u = std::clamp(u + step(rng), -1.0, 1.0);
    x = TanhPlantStep(x, u);
    e.u(k) = u;
    e.y(k) = x + noise(rng);
  }
  return e;
}

gp::NarxLayout TanhLayout() { return gp::NarxLayout{.output_lags = 1, .input_lags = 0}; }

gp::GpMpcProblem TanhMpcProblem() {
  gp::GpMpcProblem p;
  p.layout = TanhLayout();
  p.horizon = 12;
  p.output_weight = 10.0;
  p.input_change_weight = 0.1;
  p.input_min = -1.0;
  p.input_max = 1.0;
  p.rate_min = -0.5;
  p.rate_max = 0.5;
  p.output_min = -1.2;
  p.output_max = 1.2;
  p.sigma_multiple = 2.0;
  p.terminal_tolerance = 0.075;
  return p;
}

absl::StatusOr<gp::NarxData> TanhTrainingData(int points, std::uint32_t seed) {
  const TanhExperiment e = RunTanhExperiment(points + 1, seed);
  return gp::MakeNarxData(TanhLayout(), e.y, e.u);
}

double TanhReference(int k) { return k <= 50 ? -0.5 : -0.2; }

}  // namespace nupmpc::examples
