#include "loadtest/bench/gp/ipopt_gp_mpc.h"

#include <chrono>
#include <cmath>
#include <vector>

#include "IpIpoptApplication.hpp"
#include "IpSolveStatistics.hpp"
#include "IpTNLP.hpp"
#include "absl/strings/str_cat.h"

namespace nupmpc::bench {
namespace {

using Ipopt::Index;
using Ipopt::Number;

// The NLP in u[t..t+H-1]. Constraint rows: H rate limits (u[k] - u[k-1]), then H upper
// chance rows ȳ + κσ ≤ ub[k], then H lower rows ȳ - κσ ≥ lb[k] (terminal bounds folded in).
class GpMpcNlp final : public Ipopt::TNLP {
 public:
  GpMpcNlp(const gp::GpModel* model, const gp::GpMpcProblem& p) : model_(model), p_(p) {}

  void SetStep(const Eigen::VectorXd& past_outputs, const Eigen::VectorXd& past_inputs,
               const Eigen::VectorXd& reference, const Eigen::VectorXd& start) {
    past_outputs_ = past_outputs;
    past_inputs_ = past_inputs;
    reference_ = reference;
    start_ = start;
    cached_ = false;
  }
  const Eigen::VectorXd& solution() const { return solution_; }
  double objective() const { return objective_; }

  bool get_nlp_info(Index& n, Index& m, Index& nnz_jac_g, Index& nnz_h_lag, IndexStyleEnum& style) override {
    n = p_.horizon;
    m = 3 * p_.horizon;
    nnz_jac_g = m * n;  // dense (H is small)
    nnz_h_lag = 0;      // limited-memory Hessian
    style = C_STYLE;
    return true;
  }

  bool get_bounds_info(Index n, Number* x_l, Number* x_u, Index m, Number* g_l, Number* g_u) override {
    const int H = p_.horizon;
    for (int k = 0; k < n; ++k) {
      x_l[k] = p_.input_min;
      x_u[k] = p_.input_max;
    }
    const bool terminal = p_.terminal_tolerance > 0.0 && std::isfinite(p_.terminal_tolerance);
    for (int k = 0; k < H; ++k) {
      g_l[k] = p_.rate_min;
      g_u[k] = p_.rate_max;
      const bool last = terminal && k == H - 1;
      g_l[H + k] = -2e19;
      g_u[H + k] = last ? std::min(p_.output_max, reference_(k) + p_.terminal_tolerance) : p_.output_max;
      g_l[2 * H + k] = last ? std::max(p_.output_min, reference_(k) - p_.terminal_tolerance) : p_.output_min;
      g_u[2 * H + k] = 2e19;
    }
    (void)m;
    return true;
  }

  bool get_starting_point(Index n, bool init_x, Number* x, bool, Number*, Number*, Index, bool, Number*) override {
    if (init_x) {
      for (int k = 0; k < n; ++k) x[k] = start_(k);
    }
    return true;
  }

  bool eval_f(Index n, const Number* x, bool new_x, Number& obj_value) override {
    Evaluate(n, x, new_x);
    obj_value = f_;
    return true;
  }
  bool eval_grad_f(Index n, const Number* x, bool new_x, Number* grad_f) override {
    Evaluate(n, x, new_x);
    for (int k = 0; k < n; ++k) grad_f[k] = grad_f_(k);
    return true;
  }
  bool eval_g(Index n, const Number* x, bool new_x, Index m, Number* g) override {
    Evaluate(n, x, new_x);
    for (int i = 0; i < m; ++i) g[i] = g_(i);
    return true;
  }
  bool eval_jac_g(Index n, const Number* x, bool new_x, Index m, Index, Index* rows, Index* cols,
                  Number* values) override {
    if (values == nullptr) {
      for (int i = 0, e = 0; i < m; ++i) {
        for (int j = 0; j < n; ++j, ++e) {
          rows[e] = i;
          cols[e] = j;
        }
      }
      return true;
    }
    Evaluate(n, x, new_x);
    for (int i = 0, e = 0; i < m; ++i) {
      for (int j = 0; j < n; ++j, ++e) values[e] = jac_(i, j);
    }
    return true;
  }
  void finalize_solution(Ipopt::SolverReturn, Index n, const Number* x, const Number*, const Number*, Index,
                         const Number*, const Number*, Number obj_value, const Ipopt::IpoptData*,
                         Ipopt::IpoptCalculatedQuantities*) override {
    solution_ = Eigen::Map<const Eigen::VectorXd>(x, n);
    objective_ = obj_value;
  }

 private:
  // Objective, constraints and their exact first derivatives at u (cached per point).
  void Evaluate(Index n, const Number* x, bool new_x) {
    if (cached_ && !new_x) return;
    const int H = p_.horizon, l = p_.layout.output_lags, m = p_.layout.input_lags, d = p_.layout.dimension();
    const Eigen::Map<const Eigen::VectorXd> u(x, n);
    // Histories (past first) and their sensitivities to u: dy(i, :) = ∂y_hist(i)/∂u.
    Eigen::VectorXd y(l + H), uh(m + 1 + H), reg(d);
    Eigen::MatrixXd dy = Eigen::MatrixXd::Zero(l + H, H);
    dreg_.resize(H);  // ∂(regressor of ȳ[t+k])/∂u, reused for σ's gradient below
    y.head(l) = past_outputs_;
    uh.head(m + 1) = past_inputs_;
    uh.tail(H) = u;
    regressors_.resize(H, d);
    for (int k = 0; k < H; ++k) {
      gp::Regressor(p_.layout, y.segment(k, l), uh.segment(k + 1, m + 1), &reg);
      regressors_.row(k) = reg.transpose();
      y(l + k) = model_->MeanAndGradient(reg, &mean_gradient_);  // O(N d); σ comes in one batch below
      dreg_[k].resize(d, H);
      RegressorSensitivity(k, dy, &dreg_[k]);
      dy.row(l + k) = mean_gradient_.transpose() * dreg_[k];
    }
    model_->Linearise(regressors_, &lin_, &scratch_);
    f_ = 0.0;
    grad_f_ = Eigen::VectorXd::Zero(H);
    g_.resize(3 * H);
    jac_ = Eigen::MatrixXd::Zero(3 * H, H);
    double previous = past_inputs_(m);
    for (int k = 0; k < H; ++k) {
      const double e = y(l + k) - reference_(k), du = u(k) - previous;
      f_ += p_.output_weight * e * e + p_.input_change_weight * du * du;
      grad_f_ += 2.0 * p_.output_weight * e * dy.row(l + k).transpose();
      grad_f_(k) += 2.0 * p_.input_change_weight * du;
      if (k > 0) grad_f_(k - 1) -= 2.0 * p_.input_change_weight * du;
      g_(k) = du;
      jac_(k, k) = 1.0;
      if (k > 0) jac_(k, k - 1) = -1.0;
      previous = u(k);
      // σ and its gradient: ∇σ = V̂[1:, 0]/σ (∇σ² = 2 V̂[1:, 0]).
      const double sigma = std::sqrt(std::max(lin_[k].covariance(0, 0), 1e-300));
      const Eigen::RowVectorXd dsigma = (lin_[k].covariance.col(0).tail(d) / sigma).transpose() * dreg_[k];
      g_(H + k) = y(l + k) + p_.sigma_multiple * sigma;
      g_(2 * H + k) = y(l + k) - p_.sigma_multiple * sigma;
      jac_.row(H + k) = dy.row(l + k) + p_.sigma_multiple * dsigma;
      jac_.row(2 * H + k) = dy.row(l + k) - p_.sigma_multiple * dsigma;
    }
    cached_ = true;
  }

  // ∂(regressor of ȳ[t+k])/∂u from the output sensitivities so far.
  void RegressorSensitivity(int k, const Eigen::MatrixXd& dy, Eigen::MatrixXd* dreg) const {
    const int l = p_.layout.output_lags, m = p_.layout.input_lags;
    dreg->setZero();
    for (int q = 0; q < l; ++q) dreg->row(q) = dy.row(k + q);
    for (int j = 0; j <= m; ++j) {
      const int step = k - m + j;  // u[t+step]; negative steps are the fixed past
      if (step >= 0) (*dreg)(l + j, step) = 1.0;
    }
  }

  const gp::GpModel* model_;
  gp::GpMpcProblem p_;
  Eigen::VectorXd past_outputs_, past_inputs_, reference_, start_, solution_;
  double objective_ = 0.0;
  bool cached_ = false;
  double f_ = 0.0;
  Eigen::VectorXd grad_f_, g_;
  Eigen::MatrixXd jac_, regressors_;
  std::vector<gp::LinGp> lin_;
  gp::LinearisationScratch scratch_;
  Eigen::VectorXd mean_gradient_;
  std::vector<Eigen::MatrixXd> dreg_;
};

}  // namespace

struct IpoptGpMpc::Impl {
  Ipopt::SmartPtr<GpMpcNlp> nlp;
  Ipopt::SmartPtr<Ipopt::IpoptApplication> app;
  int horizon = 0;
};

IpoptGpMpc::IpoptGpMpc(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
IpoptGpMpc::~IpoptGpMpc() = default;

absl::StatusOr<std::unique_ptr<IpoptGpMpc>> IpoptGpMpc::Create(const gp::GpModel* model, gp::GpMpcProblem problem,
                                                               IpoptGpMpcOptions options) {
  if (model == nullptr) return absl::InvalidArgumentError("model: must not be null");
  if (absl::Status s = gp::Validate(problem); !s.ok()) return s;
  auto impl = std::make_unique<Impl>();
  impl->horizon = problem.horizon;
  impl->nlp = new GpMpcNlp(model, problem);
  impl->app = IpoptApplicationFactory();
  impl->app->Options()->SetNumericValue("tol", options.tolerance);
  impl->app->Options()->SetIntegerValue("max_iter", options.max_iterations);
  impl->app->Options()->SetStringValue("hessian_approximation", "limited-memory");
  impl->app->Options()->SetIntegerValue("print_level", 0);
  impl->app->Options()->SetStringValue("sb", "yes");  // no banner
  if (impl->app->Initialize() != Ipopt::Solve_Succeeded) return absl::InternalError("Ipopt failed to initialise");
  return std::unique_ptr<IpoptGpMpc>(new IpoptGpMpc(std::move(impl)));
}

absl::StatusOr<IpoptGpMpcResult> IpoptGpMpc::Solve(const Eigen::VectorXd& past_outputs,
                                                   const Eigen::VectorXd& past_inputs, const Eigen::VectorXd& reference,
                                                   const Eigen::VectorXd& initial_inputs) {
  if (initial_inputs.size() != impl_->horizon) return absl::InvalidArgumentError("initial_inputs: expected H values");
  const Eigen::VectorXd r =
      reference.size() == impl_->horizon ? reference : Eigen::VectorXd::Constant(impl_->horizon, reference(0));
  const auto start = std::chrono::steady_clock::now();
  impl_->nlp->SetStep(past_outputs, past_inputs, r, initial_inputs);
  const Ipopt::ApplicationReturnStatus status = impl_->app->OptimizeTNLP(impl_->nlp);
  IpoptGpMpcResult result;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.status = static_cast<int>(status);
  result.solved = status == Ipopt::Solve_Succeeded || status == Ipopt::Solved_To_Acceptable_Level;
  result.inputs = impl_->nlp->solution();
  result.objective = impl_->nlp->objective();
  if (Ipopt::SmartPtr<Ipopt::SolveStatistics> stats = impl_->app->Statistics(); Ipopt::IsValid(stats)) {
    result.iterations = stats->IterationCount();
  }
  return result;
}

}  // namespace nupmpc::bench
