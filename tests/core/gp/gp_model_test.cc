// GP regression and the linGP against independent references: predictions against dense
// formulas with an explicit inverse, gradients and the linGP against finite differences
// of the exact GP, V̂ positive semidefinite; the likelihood gradient against finite
// differences; the hyper-parameter fit recovers the parameters of data drawn from a
// known GP and stops within one evaluation of its time limit; NARX data layout.
#include "core/gp/gp_model.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "Eigen/LU"
#include "core/gp/blocked_cholesky.h"
#include "core/gp/hyperparameter_fit.h"
#include "core/gp/narx.h"
#include "gtest/gtest.h"

namespace nupmpc::gp {
namespace {

SeArdKernel TestKernel() {
  SeArdKernel k;
  k.signal_variance = 1.7;
  k.length_scales = Eigen::Vector2d(0.8, 1.4);
  k.noise_variance = 0.02;
  return k;
}

// The test kernel with little noise: on many points K is then numerically low-rank, the
// setting of the linearisation paths.
SeArdKernel LowNoiseKernel() {
  SeArdKernel k = TestKernel();
  k.noise_variance = 1e-3;
  return k;
}

struct Data {
  Eigen::MatrixXd x;
  Eigen::VectorXd y;
};

Data SmoothData(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> coord(-2.0, 2.0);
  Data d{Eigen::MatrixXd(n, 2), Eigen::VectorXd(n)};
  for (int i = 0; i < n; ++i) {
    d.x(i, 0) = coord(rng);
    d.x(i, 1) = coord(rng);
    d.y(i) = std::sin(d.x(i, 0)) * std::cos(0.5 * d.x(i, 1)) + 0.1 * d.x(i, 1);
  }
  return d;
}

// Dense reference: k(x,x') written out, K_y inverted by LU.
double RefKernel(const SeArdKernel& k, const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return k.signal_variance * std::exp(-0.5 * ((a - b).array() / k.length_scales.array()).square().sum());
}

TEST(GpModel, PredictionsMatchDenseFormulas) {
  const Data d = SmoothData(25, 1);
  const SeArdKernel kernel = TestKernel();
  auto model = GpModel::Create(d.x, d.y, kernel);
  ASSERT_TRUE(model.ok()) << model.status();
  Eigen::MatrixXd ky(25, 25);
  for (int i = 0; i < 25; ++i) {
    for (int j = 0; j < 25; ++j) ky(i, j) = RefKernel(kernel, d.x.row(i).transpose(), d.x.row(j).transpose());
  }
  ky.diagonal().array() += kernel.noise_variance;
  const Eigen::MatrixXd inverse = ky.fullPivLu().inverse();
  Eigen::MatrixXd probes(3, 2);
  probes << 0.3, -0.4, 1.9, 1.2, -3.0, 0.0;
  for (int p = 0; p < probes.rows(); ++p) {
    const Eigen::VectorXd x = probes.row(p).transpose();
    Eigen::VectorXd kx(25);
    for (int i = 0; i < 25; ++i) kx(i) = RefKernel(kernel, d.x.row(i).transpose(), x);
    const double ref_mean = kx.dot(inverse * d.y);
    const double ref_var = kernel.signal_variance - kx.dot(inverse * kx);
    double mean = 0.0, var = 0.0;
    model->Predict(x, &mean, &var);
    EXPECT_NEAR(mean, ref_mean, 1e-10);
    EXPECT_NEAR(var, ref_var, 1e-10);
    EXPECT_NEAR(model->Mean(x), ref_mean, 1e-10);
  }
}

TEST(GpModel, LinGpIsTheExactGpsFirstOrderExpansion) {
  const Data d = SmoothData(60, 2);
  auto model = GpModel::Create(d.x, d.y, TestKernel());
  ASSERT_TRUE(model.ok());
  const Eigen::Vector2d x(0.4, -0.7);
  const LinGp lin = model->Linearise(x);
  double mean = 0.0, var = 0.0;
  model->Predict(x, &mean, &var);
  EXPECT_NEAR(lin.mean(0), mean, 1e-12);
  EXPECT_NEAR(lin.covariance(0, 0), var, 1e-12);
  Eigen::VectorXd gradient;
  EXPECT_NEAR(model->MeanAndGradient(x, &gradient), mean, 1e-12);
  EXPECT_LT((gradient - lin.mean.tail(2)).cwiseAbs().maxCoeff(), 1e-12);
  constexpr double h = 1e-6;
  for (int i = 0; i < 2; ++i) {
    Eigen::Vector2d step = Eigen::Vector2d::Zero();
    step(i) = h;
    double mp, vp, mm, vm;
    model->Predict(x + step, &mp, &vp);
    model->Predict(x - step, &mm, &vm);
    EXPECT_NEAR(lin.mean(1 + i), (mp - mm) / (2 * h), 1e-7) << "∇μ_" << i;
    // ∂σ²/∂x_i = 2 V̂(i+1, 0): the prior cross-covariance of f and ∇f vanishes at x.
    EXPECT_NEAR(2.0 * lin.covariance(1 + i, 0), (vp - vm) / (2 * h), 1e-7) << "∇σ²_" << i;
  }
  // The linGP mean is the linearised exact mean: error O(|Δ|²).
  for (const double scale : {1e-2, 1e-3}) {
    const Eigen::Vector2d delta = scale * Eigen::Vector2d(0.6, -0.8);
    EXPECT_LT(std::abs(lin.Mean(delta) - model->Mean(x + delta)), 5.0 * scale * scale);
  }
  // V̂ is a covariance: symmetric PSD (so the linGP variance is convex in Δ).
  EXPECT_LT((lin.covariance - lin.covariance.transpose()).norm(), 1e-12);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(lin.covariance).eigenvalues().minCoeff(), -1e-10);
}

TEST(GpModel, BatchedLinearisationEqualsOneByOne) {
  const Data d = SmoothData(40, 3);
  auto model = GpModel::Create(d.x, d.y, TestKernel());
  ASSERT_TRUE(model.ok());
  Eigen::MatrixXd points(3, 2);
  points << 0.1, 0.2, -1.0, 1.5, 2.5, -0.3;
  std::vector<LinGp> batch;
  model->Linearise(points, &batch);
  ASSERT_EQ(batch.size(), 3u);
  for (int p = 0; p < 3; ++p) {
    const LinGp one = model->Linearise(Eigen::VectorXd(points.row(p).transpose()));
    EXPECT_LT((batch[p].mean - one.mean).cwiseAbs().maxCoeff(), 1e-13);
    EXPECT_LT((batch[p].covariance - one.covariance).cwiseAbs().maxCoeff(), 1e-13);
  }
}

// Linearise() uses K's numerically low-rank eigendecomposition; Predict() the Cholesky
// factor. On 1200 points the two agree to rounding, with a basis far smaller than N.
TEST(GpModel, LowRankLinearisationMatchesTheCholeskyPrediction) {
  const Data d = SmoothData(1200, 6);
  const SeArdKernel kernel = LowNoiseKernel();
  auto model = GpModel::Create(d.x, d.y, kernel);
  ASSERT_TRUE(model.ok());
  EXPECT_LT(model->basis_rank(), 300);
  Eigen::MatrixXd points(6, 2);
  points << 0.0, 0.0, 1.3, -1.7, -1.9, 1.9, 0.7, 0.2, 2.5, 2.5, -4.0, 1.0;  // inside, edge, outside the data
  std::vector<LinGp> lin;
  model->Linearise(points, &lin);
  for (int p = 0; p < 6; ++p) {
    double mean = 0.0, variance = 0.0;
    model->Predict(Eigen::VectorXd(points.row(p).transpose()), &mean, &variance);
    EXPECT_NEAR(lin[p].mean(0), mean, 1e-12);
    EXPECT_NEAR(lin[p].covariance(0, 0), variance, 1e-10 * kernel.signal_variance) << "point " << p;
  }
}

// The fast path (pivot points, O(m²) per column; Mean() too) against a dense reference of
// the whole linGP, m̂ = Wᵀ K_y⁻¹ Y and V̂ = prior - Wᵀ K_y⁻¹ W with W written out from the kernel's
// derivatives, at points inside the data (fast path) and outside it (the power check sends
// them to the O(N r) path).
TEST(GpModel, PivotFastPathMatchesTheDenseLinGpInsideAndFallsBackOutside) {
  const Data d = SmoothData(1000, 7);
  const SeArdKernel kernel = LowNoiseKernel();
  auto model = GpModel::Create(d.x, d.y, kernel);
  ASSERT_TRUE(model.ok());
  EXPECT_GT(model->num_pivots(), 0);
  EXPECT_LT(model->num_pivots(), 250);
  const int n = 1000;
  Eigen::MatrixXd ky(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) ky(i, j) = RefKernel(kernel, d.x.row(i).transpose(), d.x.row(j).transpose());
  }
  ky.diagonal().array() += kernel.noise_variance;
  const Eigen::LLT<Eigen::MatrixXd> ky_llt(ky);
  const Eigen::VectorXd alpha = ky_llt.solve(d.y);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> inside(-1.8, 1.8), outside(2.6, 4.0);
  int fast_inside = 0, fast_outside = 0;
  constexpr int kProbes = 60;
  for (int probe = 0; probe < 2 * kProbes; ++probe) {
    const bool in = probe < kProbes;
    const Eigen::Vector2d x = in ? Eigen::Vector2d(inside(rng), inside(rng))
                                 : Eigen::Vector2d(outside(rng), (probe % 2 ? 1 : -1) * outside(rng));
    Eigen::MatrixXd w(n, 3);  // [k, ∂k/∂x_1, ∂k/∂x_2](X_j, x)
    for (int j = 0; j < n; ++j) {
      const double k = RefKernel(kernel, d.x.row(j).transpose(), x);
      w(j, 0) = k;
      for (int i = 0; i < 2; ++i) w(j, 1 + i) = -k * (x(i) - d.x(j, i)) / std::pow(kernel.length_scales(i), 2);
    }
    Eigen::Matrix3d prior = Eigen::Matrix3d::Zero();
    prior(0, 0) = kernel.signal_variance;
    for (int i = 0; i < 2; ++i) prior(1 + i, 1 + i) = kernel.signal_variance / std::pow(kernel.length_scales(i), 2);
    const Eigen::Vector3d mean = w.transpose() * alpha;
    const Eigen::Matrix3d covariance = prior - w.transpose() * ky_llt.solve(w);
    std::vector<LinGp> lin;
    const int fast = model->Linearise(Eigen::MatrixXd(x.transpose()), &lin);
    (in ? fast_inside : fast_outside) += fast;
    EXPECT_LT((lin[0].mean - mean).cwiseAbs().maxCoeff(), 1e-9) << "probe " << probe << " fast " << fast;
    EXPECT_NEAR(model->Mean(x), mean(0), 1e-9) << "probe " << probe;
    EXPECT_LT((lin[0].covariance - covariance).cwiseAbs().maxCoeff(), 1e-9 * prior.maxCoeff())
        << "probe " << probe << " fast " << fast;
  }
  EXPECT_GE(fast_inside, kProbes * 9 / 10);  // the fast path is the common case inside
  EXPECT_LT(fast_outside, kProbes);          // and not taken everywhere outside
  RecordProperty("fast_inside", fast_inside);
  RecordProperty("fast_outside", fast_outside);
  std::printf("pivots %d of %d points; fast path at %d/%d points inside, %d/%d outside\n", model->num_pivots(), n,
              fast_inside, kProbes, fast_outside, kProbes);
}

TEST(GpModel, BadInputIsRefusedNamingTheField) {
  const Data d = SmoothData(5, 4);
  SeArdKernel k = TestKernel();
  k.length_scales(1) = -1.0;
  EXPECT_NE(GpModel::Create(d.x, d.y, k).status().message().find("length_scales[1]"), std::string::npos);
  EXPECT_NE(GpModel::Create(d.x, Eigen::VectorXd::Zero(4), TestKernel()).status().message().find("targets"),
            std::string::npos);
  k = TestKernel();
  k.noise_variance = 0.0;
  EXPECT_NE(GpModel::Create(d.x, d.y, k).status().message().find("noise_variance"), std::string::npos);
}

TEST(HyperparameterFit, LikelihoodGradientMatchesFiniteDifferences) {
  const Data d = SmoothData(30, 5);
  const SeArdKernel kernel = TestKernel();
  Eigen::VectorXd gradient;
  ASSERT_TRUE(NegativeLogLikelihood(d.x, d.y, kernel, &gradient).ok());
  constexpr double h = 1e-6;
  const auto nll_with = [&](int j, double step) {
    SeArdKernel k = kernel;
    if (j == 0) k.signal_variance *= std::exp(step);
    if (j == 1 || j == 2) k.length_scales(j - 1) *= std::exp(step);
    if (j == 3) k.noise_variance *= std::exp(step);
    return *NegativeLogLikelihood(d.x, d.y, k, nullptr);
  };
  for (int j = 0; j < 4; ++j) {
    const double fd = (nll_with(j, h) - nll_with(j, -h)) / (2 * h);
    EXPECT_NEAR(gradient(j), fd, 1e-5 * (1.0 + std::abs(fd))) << "log-parameter " << j;
  }
}

// Data drawn from a GP with known hyper-parameters: the fit finds a likelihood at least as
// good as the truth's and parameters close to it.
TEST(HyperparameterFit, RecoversKnownParameters) {
  constexpr int n = 300;
  SeArdKernel truth;
  truth.signal_variance = 1.5;
  truth.length_scales = Eigen::Vector2d(0.7, 1.6);
  truth.noise_variance = 0.01;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> coord(-3.0, 3.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::MatrixXd x(n, 2);
  for (int i = 0; i < n; ++i) x.row(i) << coord(rng), coord(rng);
  Eigen::MatrixXd ky = KernelMatrix(truth, x);
  ky.diagonal().array() += truth.noise_variance;
  Eigen::VectorXd z(n);
  for (int i = 0; i < n; ++i) z(i) = normal(rng);
  const Eigen::VectorXd y = Eigen::LLT<Eigen::MatrixXd>(ky).matrixL() * z;

  SeArdKernel start;
  start.signal_variance = 1.0;
  start.length_scales = Eigen::Vector2d(1.0, 1.0);
  start.noise_variance = 0.1;
  auto fit = FitHyperparameters(x, y, start);
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_TRUE(fit->converged) << fit->report;
  EXPECT_LE(fit->negative_log_likelihood, *NegativeLogLikelihood(x, y, truth, nullptr) + 1e-6);
  EXPECT_LT(fit->gradient_norm, 1e-3);
  EXPECT_NEAR(std::log(fit->kernel.length_scales(0) / truth.length_scales(0)), 0.0, std::log(1.3));
  EXPECT_NEAR(std::log(fit->kernel.length_scales(1) / truth.length_scales(1)), 0.0, std::log(1.3));
  EXPECT_NEAR(std::log(fit->kernel.noise_variance / truth.noise_variance), 0.0, std::log(1.5));
  EXPECT_NEAR(std::log(fit->kernel.signal_variance / truth.signal_variance), 0.0, std::log(2.5));
}

// Seconds one likelihood-and-gradient evaluation takes on `d`, measured now (the fit's
// stop latency is stated in evaluations, not in absolute time).
double EvaluationSeconds(const Data& d) {
  Eigen::VectorXd gradient;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_TRUE(NegativeLogLikelihood(d.x, d.y, TestKernel(), &gradient).ok());
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The limit is checked before every O(P³) evaluation: once it has passed, at most the
// evaluation under way finishes, and the result is the last accepted iterate.
TEST(HyperparameterFit, StopsAtItsTimeLimitWithinOneEvaluation) {
  const Data d = SmoothData(600, 3);
  const double evaluation = EvaluationSeconds(d);
  FitOptions options;
  options.max_seconds = 3 * evaluation;  // far fewer evaluations than the fit needs
  auto fit = FitHyperparameters(d.x, d.y, TestKernel(), options);
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_TRUE(fit->stopped) << fit->report;
  EXPECT_FALSE(fit->converged);
  // One evaluation measured again after the fit as well: on a shared machine whose load
  // changed meanwhile, the slower of the two is the fit's evaluation.
  const double slower_evaluation = std::max(evaluation, EvaluationSeconds(d));
  EXPECT_LT(fit->seconds, options.max_seconds + 2 * slower_evaluation)
      << fit->report << "; one evaluation " << evaluation << " s before the fit, " << slower_evaluation << " s at most";
  EXPECT_LE(fit->negative_log_likelihood, fit->initial_negative_log_likelihood);
  // What it reports is the likelihood at the kernel it returns.
  EXPECT_NEAR(fit->negative_log_likelihood, *NegativeLogLikelihood(d.x, d.y, fit->kernel, nullptr),
              1e-9 * std::abs(fit->negative_log_likelihood));
}

TEST(HyperparameterFit, ARaisedCancelFlagStopsTheFitBeforeItsFirstIteration) {
  const Data d = SmoothData(300, 4);
  const std::atomic<bool> cancel{true};
  FitOptions options;
  options.cancel = &cancel;
  auto fit = FitHyperparameters(d.x, d.y, TestKernel(), options);
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_TRUE(fit->stopped);
  EXPECT_EQ(fit->iterations, 0);
  // Stopped inside the first evaluation: the start is returned, its likelihood unknown.
  EXPECT_EQ(fit->kernel.length_scales, TestKernel().length_scales);
  EXPECT_TRUE(std::isnan(fit->negative_log_likelihood));
}

// The blocked factorisation and inverse against Eigen's, on a size that is not a multiple
// of the block; a raised flag or a passed deadline stops them with the matching code.
TEST(BlockedCholesky, MatchesEigenAndStopsWhenAsked) {
  const int n = 2 * kCholeskyBlock + 37;
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd b(n, n);
  for (Eigen::Index i = 0; i < b.size(); ++i) b.data()[i] = normal(rng);
  Eigen::MatrixXd a = b * b.transpose();
  a.diagonal().array() += n;
  Eigen::MatrixXd f = a;
  ASSERT_TRUE(BlockedCholesky(f, core::Deadline{}, "A").ok());
  const Eigen::MatrixXd reference = a.llt().matrixL();
  const Eigen::MatrixXd lower = f.triangularView<Eigen::Lower>();
  EXPECT_LT((lower - reference).norm(), 1e-12 * reference.norm());
  Eigen::MatrixXd scratch(kCholeskyBlock, n + kCholeskyBlock);
  ASSERT_TRUE(InverseFromCholesky(f, &scratch, core::Deadline{}, "A").ok());
  const Eigen::MatrixXd inverse = f.selfadjointView<Eigen::Lower>();
  EXPECT_LT((inverse * a - Eigen::MatrixXd::Identity(n, n)).norm(), 1e-10);

  Eigen::MatrixXd indefinite = a;
  indefinite(n - 1, n - 1) = -1.0;
  EXPECT_EQ(BlockedCholesky(indefinite, core::Deadline{}, "A").code(), absl::StatusCode::kFailedPrecondition);
  const std::atomic<bool> cancel{true};
  core::Deadline cancelled;
  cancelled.cancel = &cancel;
  f = a;
  EXPECT_EQ(BlockedCholesky(f, cancelled, "A").code(), absl::StatusCode::kCancelled);
  core::Deadline passed;
  passed.at = core::Deadline::Clock::now();
  f = a;
  const absl::Status late = BlockedCholesky(f, passed, "A");
  EXPECT_EQ(late.code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_NE(late.message().find("factorising A (column 0 of"), absl::string_view::npos) << late;
  EXPECT_EQ(InverseFromCholesky(f, &scratch, passed, "A").code(), absl::StatusCode::kDeadlineExceeded);
}

// A model's set-up and a likelihood evaluation stop at a raised flag or a passed deadline,
// saying in which step.
TEST(GpModel, SetUpAndLikelihoodStopWhenAsked) {
  const Data d = SmoothData(600, 3);
  const std::atomic<bool> cancel{true};
  core::Deadline cancelled;
  cancelled.cancel = &cancel;
  absl::StatusOr<GpModel> model = GpModel::Create(d.x, d.y, TestKernel(), cancelled);
  EXPECT_EQ(model.status().code(), absl::StatusCode::kCancelled);
  EXPECT_NE(model.status().message().find("step 1 of 3"), absl::string_view::npos) << model.status();
  core::Deadline passed;
  passed.at = core::Deadline::Clock::now();
  model = GpModel::Create(d.x, d.y, TestKernel(), passed);
  EXPECT_EQ(model.status().code(), absl::StatusCode::kDeadlineExceeded);
  LikelihoodWorkspace workspace;
  Eigen::VectorXd gradient;
  EXPECT_EQ(NegativeLogLikelihood(d.x, d.y, TestKernel(), &gradient, cancelled, &workspace).status().code(),
            absl::StatusCode::kCancelled);
  // The workspace is reusable after a stop, and gives what the plain evaluation gives.
  Eigen::VectorXd plain_gradient;
  const absl::StatusOr<double> reused = NegativeLogLikelihood(d.x, d.y, TestKernel(), &gradient, {}, &workspace);
  const absl::StatusOr<double> plain = NegativeLogLikelihood(d.x, d.y, TestKernel(), &plain_gradient);
  ASSERT_TRUE(reused.ok() && plain.ok());
  EXPECT_EQ(*reused, *plain);
  EXPECT_EQ(gradient, plain_gradient);
}

// Too few points for a low-rank factor to pay off: the linGP takes the exact path through
// the Cholesky factor and agrees with Predict().
TEST(GpModel, WithoutALowRankFactorTheExactPathMatchesPredict) {
  const Data d = SmoothData(40, 8);
  auto model = GpModel::Create(d.x, d.y, LowNoiseKernel());
  ASSERT_TRUE(model.ok());
  EXPECT_EQ(model->basis_rank(), 0);
  EXPECT_EQ(model->num_pivots(), 0);
  Eigen::MatrixXd points(3, 2);
  points << 0.0, 0.0, 1.3, -1.7, -4.0, 1.0;
  std::vector<LinGp> lin;
  model->Linearise(points, &lin);
  for (int p = 0; p < 3; ++p) {
    double mean = 0.0, variance = 0.0;
    model->Predict(Eigen::VectorXd(points.row(p).transpose()), &mean, &variance);
    EXPECT_NEAR(lin[p].mean(0), mean, 1e-12);
    EXPECT_NEAR(lin[p].covariance(0, 0), variance, 1e-12) << "point " << p;
  }
}

TEST(Narx, RegressorsFollowTheLayout) {
  Eigen::VectorXd y(6), u(6);
  y << 0, 1, 2, 3, 4, 5;
  u << 10, 11, 12, 13, 14, 15;
  auto data = MakeNarxData(NarxLayout{.output_lags = 2, .input_lags = 1}, y, u);
  ASSERT_TRUE(data.ok());
  ASSERT_EQ(data->regressors.rows(), 4);  // k = 2..5
  // y[k] from [y[k-2], y[k-1], u[k-1], u[k]].
  EXPECT_EQ(data->regressors.row(0), Eigen::RowVector4d(0, 1, 11, 12));
  EXPECT_EQ(data->targets(0), 2);
  EXPECT_EQ(data->regressors.row(3), Eigen::RowVector4d(3, 4, 14, 15));
  EXPECT_FALSE(MakeNarxData(NarxLayout{.output_lags = 0}, y, u).ok());
}

}  // namespace
}  // namespace nupmpc::gp
