#include "client/nonlinear_session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <tuple>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/nonlinear_session_rules.h"
#include "client/spec_update.h"
#include "client/status_macros.h"

namespace nupmpc {

using nonlinear_internal::AffineTerm;
using nonlinear_internal::EvalOutput;
using nonlinear_internal::EvalTransition;
using nonlinear_internal::Jacobians;
using nonlinear_internal::OutputJacobian;
using nonlinear_internal::TransitionJacobians;
using nonlinear_internal::ValidateModel;
using nonlinear_internal::ValidateOptions;
using nonlinear_internal::ValidateSpec;

namespace {

using Vector = std::vector<double>;
constexpr double kInfinity = std::numeric_limits<double>::infinity();

class Stopwatch {
 public:
  double ms() const {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

double MaxAbs(const Vector& v) {
  double m = 0.0;
  for (const double x : v) m = std::max(m, std::abs(x));
  return m;
}

double MaxAbsDifference(const Vector& a, const Vector& b) {
  double m = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}

Vector Slice(const Vector& v, int row, int width) {
  return Vector(v.begin() + static_cast<std::ptrdiff_t>(row) * width,
                v.begin() + static_cast<std::ptrdiff_t>(row + 1) * width);
}

// The components with a finite entry, with that entry.
std::vector<std::pair<int, double>> FiniteEntries(const Vector& values) {
  std::vector<std::pair<int, double>> entries;
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (std::isfinite(values[i])) entries.emplace_back(static_cast<int>(i), values[i]);
  }
  return entries;
}

// Entry n of a per-step array (empty: `absent`; one value: the same at every step).
double PerStep(const google::protobuf::RepeatedField<double>& values, int n, double absent) {
  if (values.empty()) return absent;
  return values.size() == 1 ? values.Get(0) : values.Get(n);
}

v1::Matrix ToMatrix(int rows, int cols, const Vector& data) {
  v1::Matrix m;
  m.set_rows(rows);
  m.set_cols(cols);
  m.mutable_data()->Add(data.begin(), data.end());
  return m;
}

}  // namespace

NonlinearSession::NonlinearSession(NonlinearModel model, NonlinearSessionOptions options, v1::ProblemSpec base,
                                   int horizon)
    : model_(std::move(model)), options_(std::move(options)), base_(std::move(base)), horizon_(horizon) {
  trusted_ = FiniteEntries(options_.region.state_radius);
  damped_ = FiniteEntries(options_.region.state_proximal_stddev);
  damped_inputs_ = FiniteEntries(options_.region.input_proximal_stddev);
}

absl::StatusOr<std::unique_ptr<NonlinearSession>> NonlinearSession::Create(Client& client, NonlinearModel model,
                                                                           v1::ProblemSpec spec,
                                                                           NonlinearSessionOptions options,
                                                                           InitialGuess guess) {
  NUPMPC_CLIENT_RETURN_IF_ERROR(ValidateModel(model));
  NUPMPC_CLIENT_RETURN_IF_ERROR(ValidateOptions(options, model));
  NUPMPC_CLIENT_RETURN_IF_ERROR(ValidateSpec(spec, model));
  const int N = static_cast<int>(spec.model().horizon()), M = model.num_states, L = model.num_inputs;
  const std::size_t states = static_cast<std::size_t>(N + 1) * M, inputs = static_cast<std::size_t>(N) * L;
  Point point;
  point.inputs = guess.inputs.empty() ? Vector(inputs, 0.0) : std::move(guess.inputs);
  const auto& x0 = spec.initial_state().mean();
  if (guess.states.empty()) {
    for (int n = 0; n <= N; ++n) point.states.insert(point.states.end(), x0.begin(), x0.end());
  } else {
    point.states = std::move(guess.states);
  }
  if (point.inputs.size() != inputs || point.states.size() != states) {
    return absl::InvalidArgumentError(absl::StrCat("InitialGuess: expected inputs N×L = ", inputs,
                                                   " and states (N+1)×M = ", states, " values, got ",
                                                   point.inputs.size(), " and ", point.states.size()));
  }
  // x[0] is the initial state, whatever the guess says.
  std::copy(x0.begin(), x0.end(), point.states.begin());
  if (options.check_jacobians) {
    // Along the whole guess: an entry that is wrong only where some state is far from zero
    // (a speed, a steering angle) shows at some step more likely than at one.
    for (int n = 0; n < N; ++n) {
      NUPMPC_CLIENT_RETURN_IF_ERROR(nupmpc::CheckJacobians(model, n, Slice(point.states, n, M),
                                                           Slice(point.inputs, n, L), options.jacobian_tolerance,
                                                           options.finite_difference_step));
    }
  }
  std::unique_ptr<NonlinearSession> session(new NonlinearSession(std::move(model), std::move(options), spec, N));
  // The model, written per step from the start: the server then stores N matrices (N + 1
  // for C), and every later update replaces them without rebuilding (the warm start stays).
  v1::ModelUpdate linearised;
  NUPMPC_CLIENT_RETURN_IF_ERROR(session->LinearisedModel(point, 0, &linearised));
  v1::Model* m = spec.mutable_model();
  const int K = session->model_.num_outputs;
  m->set_num_states(M);
  m->set_num_inputs(L);
  m->set_num_outputs(K + session->extra_outputs());
  for (const auto& a : linearised.a()) *m->add_a() = a.matrix();
  for (const auto& b : linearised.b()) *m->add_b() = b.matrix();
  for (const auto& c : linearised.c()) *m->add_c() = c.matrix();
  *m->mutable_state_offset() = linearised.state_offsets();
  *m->mutable_output_offset() = linearised.output_offsets();
  v1::PriorUpdate region;
  session->RegionPriors(point, 1.0, session->base_, &region);
  for (const auto& entry : region.outputs()) *spec.add_output_priors() = entry.prior();  // in order K, K+1, ...
  for (const auto& entry : region.inputs()) *spec.mutable_input_priors(static_cast<int>(entry.index())) = entry.prior();
  absl::StatusOr<std::unique_ptr<Session>> opened = client.OpenSession(spec);
  if (!opened.ok()) return opened.status();
  session->session_ = *std::move(opened);
  session->session_id_ = session->session_->id();
  session->next_point_ = std::move(point);
  return session;
}

absl::Status NonlinearSession::LinearisedModel(const Point& point, std::int64_t t0, v1::ModelUpdate* update) const {
  const int N = horizon_, M = model_.num_states, L = model_.num_inputs, K = model_.num_outputs, T = extra_outputs();
  for (int n = 0; n <= N; ++n) {
    const Vector x = Slice(point.states, n, M);
    Jacobians j;
    if (n < N) {
      const Vector u = Slice(point.inputs, n, L);
      absl::StatusOr<Jacobians> f = TransitionJacobians(model_, t0 + n, x, u, false, options_.finite_difference_step);
      if (!f.ok()) return f.status();
      j = *std::move(f);
      v1::ModelUpdate::MatrixAt* a = update->add_a();
      a->set_step(n);
      *a->mutable_matrix() = ToMatrix(M, M, j.A);
      v1::ModelUpdate::MatrixAt* b = update->add_b();
      b->set_step(n);
      *b->mutable_matrix() = ToMatrix(M, L, j.B);
      const Vector c = AffineTerm(AffineTerm(j.fx, j.A, x), j.B, u);
      update->mutable_state_offsets()->Add(c.begin(), c.end());
    }
    if (K + T == 0) continue;
    NUPMPC_CLIENT_RETURN_IF_ERROR(OutputJacobian(model_, t0 + n, x, false, options_.finite_difference_step, &j));
    // The region's extra outputs observe single states: rows of the identity from step 1
    // on (x[0] is measured, nothing to keep near), zero at step 0.
    Vector C = j.C;
    C.resize(static_cast<std::size_t>(K + T) * M, 0.0);
    if (n > 0) {
      int row = K;
      for (const auto& [state, radius] : trusted_) C[static_cast<std::size_t>(row++) * M + state] = 1.0;
      for (const auto& [state, stddev] : damped_) C[static_cast<std::size_t>(row++) * M + state] = 1.0;
    }
    v1::ModelUpdate::MatrixAt* c = update->add_c();
    c->set_step(n);
    *c->mutable_matrix() = ToMatrix(K + T, M, C);
    Vector d = AffineTerm(j.hx, j.C, x);
    d.resize(K + T, 0.0);
    update->mutable_output_offsets()->Add(d.begin(), d.end());
  }
  return absl::OkStatus();
}

void NonlinearSession::RegionPriors(const Point& point, double scale, const v1::ProblemSpec& base_spec,
                                    v1::PriorUpdate* update) const {
  const int N = horizon_, M = model_.num_states, L = model_.num_inputs, K = model_.num_outputs;
  int index = K;
  for (const auto& [state, radius] : trusted_) {
    v1::PriorUpdate::Entry* entry = update->add_outputs();
    entry->set_index(index++);
    v1::ComponentPrior* p = entry->mutable_prior();
    p->set_kind(v1::PRIOR_KIND_BOX);
    for (int n = 0; n <= N; ++n) {
      const double x = point.states[static_cast<std::size_t>(n) * M + state];
      p->add_lower(n == 0 ? -kInfinity : x - radius);
      p->add_upper(n == 0 ? kInfinity : x + radius);
    }
  }
  for (const auto& [state, unscaled] : damped_) {
    v1::PriorUpdate::Entry* entry = update->add_outputs();
    entry->set_index(index++);
    v1::ComponentPrior* p = entry->mutable_prior();
    const double weight = 1.0 / (scale * unscaled * scale * unscaled);
    for (int n = 0; n <= N; ++n) {
      p->add_weight(n == 0 ? 0.0 : weight);
      p->add_target(point.states[static_cast<std::size_t>(n) * M + state]);
    }
  }
  for (const auto& [input, unscaled] : damped_inputs_) {
    // The user's prior with N(ū, σ²) folded into its Gaussian part: precisions add, and the
    // target is the precision-weighted mean.
    v1::PriorUpdate::Entry* entry = update->add_inputs();
    entry->set_index(input);
    const v1::ComponentPrior& base = base_spec.input_priors(input);
    v1::ComponentPrior* p = entry->mutable_prior();
    *p = base;
    p->clear_weight();
    p->clear_target();
    const double proximal = 1.0 / (scale * unscaled * scale * unscaled);
    for (int n = 0; n < N; ++n) {
      const double w = PerStep(base.weight(), n, 0.0), target = PerStep(base.target(), n, 0.0);
      const double u = point.inputs[static_cast<std::size_t>(n) * L + input];
      p->add_weight(w + proximal);
      p->add_target((w * target + proximal * u) / (w + proximal));
    }
  }
}

absl::StatusOr<double> NonlinearSession::ModelDefect(const Point& plan, const Vector& outputs, std::int64_t t0) const {
  const int N = horizon_, M = model_.num_states, L = model_.num_inputs, K = model_.num_outputs;
  double worst = 0.0;
  for (int n = 0; n <= N; ++n) {
    const Vector x = Slice(plan.states, n, M);
    if (n < N) {
      absl::StatusOr<Vector> next = EvalTransition(model_, t0 + n, x, Slice(plan.inputs, n, L));
      if (!next.ok()) return next.status();
      worst = std::max(worst, MaxAbsDifference(*next, Slice(plan.states, n + 1, M)));
    }
    if (K > 0) {
      absl::StatusOr<Vector> y = EvalOutput(model_, t0 + n, x);
      if (!y.ok()) return y.status();
      worst = std::max(worst, MaxAbsDifference(*y, Slice(outputs, n, K)));
    }
  }
  return worst;
}

absl::StatusOr<NonlinearSession::Point> NonlinearSession::Shifted(const Point& plan, std::int64_t t0) const {
  const int N = horizon_, M = model_.num_states, L = model_.num_inputs;
  Point shifted;
  shifted.states.assign(plan.states.begin() + M, plan.states.end());
  shifted.inputs.assign(plan.inputs.begin() + L, plan.inputs.end());
  const Vector last_input = Slice(plan.inputs, N - 1, L);
  shifted.inputs.insert(shifted.inputs.end(), last_input.begin(), last_input.end());
  // The new last state continues the plan under its last input, so that the point is a
  // trajectory of the model to its end (a repeated state would not be one).
  absl::StatusOr<Vector> next = EvalTransition(model_, t0 + N, Slice(plan.states, N, M), last_input);
  if (!next.ok()) return next.status();
  shifted.states.insert(shifted.states.end(), next->begin(), next->end());
  return shifted;
}

NonlinearSession::Point NonlinearSession::PlanPoint(const v1::SolveResult& result) const {
  return Point{Vector(result.states().begin(), result.states().end()),
               Vector(result.inputs().begin(), result.inputs().end())};
}

Vector NonlinearSession::ModelOutputs(const v1::SolveResult& result) const {
  const int K = model_.num_outputs, width = K + extra_outputs();
  Vector outputs;
  outputs.reserve(static_cast<std::size_t>(horizon_ + 1) * K);
  for (int n = 0; n <= horizon_; ++n) {
    outputs.insert(outputs.end(), result.outputs().begin() + n * width, result.outputs().begin() + n * width + K);
  }
  return outputs;
}

absl::Status NonlinearSession::CheckJacobians() const {
  const int M = model_.num_states, L = model_.num_inputs;
  for (int n = 0; n < horizon_; ++n) {
    NUPMPC_CLIENT_RETURN_IF_ERROR(nupmpc::CheckJacobians(model_, periods_ + n, Slice(next_point_.states, n, M),
                                                         Slice(next_point_.inputs, n, L), options_.jacobian_tolerance,
                                                         options_.finite_difference_step));
  }
  return absl::OkStatus();
}

absl::StatusOr<NonlinearPlan> NonlinearSession::Step(const std::vector<double>& measured_state,
                                                     const v1::PriorUpdate& update) {
  const Stopwatch period;
  const int M = model_.num_states, K = model_.num_outputs;
  if (measured_state.size() != static_cast<std::size_t>(M)) {
    return absl::InvalidArgumentError(
        absl::StrCat("measured_state: expected ", M, " values (num_states), got ", measured_state.size()));
  }
  for (const auto& entry : update.outputs()) {
    if (entry.index() >= static_cast<unsigned>(K)) {
      return absl::InvalidArgumentError(absl::StrCat("update.outputs: index ", entry.index(),
                                                     " is not one of the model's ", K,
                                                     " outputs (the ones after them belong to the linearisation "
                                                     "region)"));
    }
  }
  const std::int64_t t0 = periods_;
  Point point = next_point_;
  std::copy(measured_state.begin(), measured_state.end(), point.states.begin());
  // The user's priors as the server will hold them after this update, for the merged input
  // priors; kept once the server has accepted the period's first step.
  v1::ProblemSpec base = base_;
  {
    v1::Step user;
    *user.mutable_update() = update;
    ApplyStepToSpec(user, v1::SolveResult(), &base);
  }
  // The damped inputs' entries of `update` go out merged with their proximal terms
  // (RegionPriors), in place of the user's.
  v1::PriorUpdate first_priors = update;
  auto* user_inputs = first_priors.mutable_inputs();
  const auto damped = [this](const v1::PriorUpdate::Entry& e) {
    return std::any_of(damped_inputs_.begin(), damped_inputs_.end(),
                       [&](const auto& d) { return d.first == static_cast<int>(e.index()); });
  };
  user_inputs->erase(std::remove_if(user_inputs->begin(), user_inputs->end(), damped), user_inputs->end());

  // Once the server has taken the period's first step, the session has moved on a period
  // whatever happens later: the next period starts from this one's plan (or point).
  bool moved_on = false;
  NonlinearPlan answer;
  const auto finish_period = [&]() -> absl::Status {
    absl::StatusOr<Point> next = Shifted(answer.has_plan ? Point{answer.states, answer.inputs} : point, t0);
    if (!next.ok()) return next.status();
    next_point_ = *std::move(next);
    ++periods_;
    return absl::OkStatus();
  };
  const auto fail = [&](const absl::Status& status, int k) {
    if (moved_on) (void)finish_period();
    return absl::Status(status.code(), absl::StrCat("period ", t0, ", linearisation ", k, ": ", status.message()));
  };

  const StepControl& control = options_.step_control;
  double scale = 1.0, accepted_defect = kInfinity;
  bool accepted = false;
  PeriodReport& report = answer.report;
  for (int k = 0; k < options_.max_linearisations; ++k) {
    v1::Step step;
    step.mutable_state()->Add(measured_state.begin(), measured_state.end());
    step.set_warm_start(k == 0 ? options_.warm_start : v1::WARM_START_KEEP);
    step.set_max_iterations(options_.max_iterations);
    {
      const Stopwatch linearising;
      if (absl::Status s = LinearisedModel(point, t0, step.mutable_model()); !s.ok()) return fail(s, k);
      report.linearise_ms += linearising.ms();
    }
    v1::PriorUpdate priors = k == 0 ? first_priors : v1::PriorUpdate();
    RegionPriors(point, scale, base, &priors);
    if (priors.shift() || priors.inputs_size() > 0 || priors.outputs_size() > 0) {
      *step.mutable_update() = std::move(priors);
    }
    absl::StatusOr<v1::SolveResult> result = session_->Step(step);
    if (!result.ok()) return fail(result.status(), k);
    if (k == 0) {
      base_ = base;
      moved_on = true;
    }
    ++report.linearisations;
    report.passes += static_cast<int>(result->iterations());
    report.solve_passes.push_back(static_cast<int>(result->iterations()));
    report.keep_out_linearisations += static_cast<int>(result->linearisations());
    report.solve_ms += result->solve_ms();
    if (!result->has_plan()) {
      if (!answer.has_plan) answer.result = *std::move(result);
      break;
    }
    const Point plan = PlanPoint(*result);
    Vector outputs = ModelOutputs(*result);
    absl::StatusOr<double> defect = ModelDefect(plan, outputs, t0);
    if (!defect.ok()) return fail(defect.status(), k);
    const double step_size =
        std::max(MaxAbsDifference(plan.states, point.states), MaxAbsDifference(plan.inputs, point.inputs));
    // Step control (step_control.h): a discarded plan keeps the point and narrows the
    // proximal terms.
    const bool rejected = control.Rejects(
        StepTrial{result->status() == v1::SOLVE_STATUS_ITERATION_LIMIT, *defect, step_size}, accepted_defect);
    if (rejected) {
      ++report.rejected;
      scale = control.Shrunk(scale);
      if (accepted) continue;
      // Kept only as the answer of last resort: no plan of this period accepted yet.
    }
    answer.has_plan = true;
    answer.inputs = plan.inputs;
    answer.states = plan.states;
    answer.outputs = std::move(outputs);
    answer.result = *std::move(result);
    report.model_defect = *defect;
    if (rejected) continue;
    accepted = true;
    accepted_defect = *defect;
    report.last_step = step_size / (1.0 + std::max(MaxAbs(plan.states), MaxAbs(plan.inputs)));
    const v1::SolveStatus status = answer.result.status();
    const bool solved = status == v1::SOLVE_STATUS_CONVERGED;
    if (solved) scale = control.Grown(scale);
    point = plan;
    if (solved && (options_.max_linearisations == 1 ||
                   report.last_step <= options_.step_tolerance * control.ToleranceFactor(scale))) {
      report.converged = true;
      break;
    }
    if (status == v1::SOLVE_STATUS_TIME_LIMIT || status == v1::SOLVE_STATUS_CANCELLED) break;
  }
  // The next period linearises along this plan moved one step on (or, without a plan,
  // along this period's point moved on).
  NUPMPC_CLIENT_RETURN_IF_ERROR(finish_period());
  report.period_ms = period.ms();
  return answer;
}

}  // namespace nupmpc
