// A client session that the client re-creates after a server restart is the session the
// server had (client/spec_update.h, the client's mirror of the server's step semantics):
// for a plain session with prior updates and shifts, one with model updates, a Δu session
// and a GP session, the re-created session's next plan equals, to 1e-9, that of a session
// that never restarted, solved cold as the re-created one is.
#include <cmath>
#include <vector>

#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

class ReconnectFidelityTest : public ServiceTest {
 protected:
  // A new server on the same port, as after a crash and restart.
  void RestartServer() {
    const int port = server_->port();
    server_->Shutdown();
    server_.reset();
    server::ServerOptions options = DefaultOptions();
    options.address = "127.0.0.1:" + std::to_string(port);
    absl::StatusOr<std::unique_ptr<server::GrpcServer>> restarted = server::GrpcServer::Start(options);
    ASSERT_TRUE(restarted.ok()) << restarted.status();
    server_ = *std::move(restarted);
  }

  // Runs `before` on a session of `spec`, restarts the server, sends `next` (which the
  // client resends to the session it re-creates), and compares that plan with the one a
  // session that saw the same steps without a restart gives for `next` solved cold.
  void ExpectSamePlanAfterRestart(const v1::ProblemSpec& spec, const std::vector<v1::Step>& before,
                                  const v1::Step& next) {
    absl::StatusOr<std::unique_ptr<Session>> restarted = client_->OpenSession(spec);
    ASSERT_TRUE(restarted.ok()) << restarted.status();
    std::vector<v1::SolveResult> plans;
    for (const v1::Step& step : before) {
      absl::StatusOr<v1::SolveResult> r = (*restarted)->Step(step);
      ASSERT_TRUE(r.ok()) << r.status();
      ASSERT_TRUE(r->has_plan());
      plans.push_back(*std::move(r));
    }
    ASSERT_NO_FATAL_FAILURE(RestartServer());
    absl::StatusOr<v1::SolveResult> after = (*restarted)->Step(next);
    ASSERT_TRUE(after.ok()) << after.status();
    ASSERT_EQ((*restarted)->reconnects(), 1);
    ASSERT_TRUE(after->has_plan());
    EXPECT_FALSE(after->warm_started());

    absl::StatusOr<std::unique_ptr<Session>> uninterrupted = client_->OpenSession(spec);
    ASSERT_TRUE(uninterrupted.ok()) << uninterrupted.status();
    for (std::size_t i = 0; i < before.size(); ++i) {
      absl::StatusOr<v1::SolveResult> r = (*uninterrupted)->Step(before[i]);
      ASSERT_TRUE(r.ok()) << r.status();
      // The same steps on the same kind of server: the same plans, so the same u[0]
      // carried by a Δu session.
      ASSERT_EQ(r->inputs(0), plans[i].inputs(0)) << "step " << i;
    }
    v1::Step cold = next;
    cold.set_warm_start(v1::WARM_START_COLD);
    absl::StatusOr<v1::SolveResult> expected = (*uninterrupted)->Step(cold);
    ASSERT_TRUE(expected.ok()) << expected.status();
    ASSERT_TRUE(expected->has_plan());
    EXPECT_EQ((*uninterrupted)->reconnects(), 0);

    EXPECT_EQ(after->status(), expected->status());
    EXPECT_NEAR(after->objective(), expected->objective(), 1e-9 * std::max(1.0, std::abs(expected->objective())));
    ASSERT_EQ(after->inputs_size(), expected->inputs_size());
    for (int i = 0; i < expected->inputs_size(); ++i) {
      EXPECT_NEAR(after->inputs(i), expected->inputs(i), 1e-9) << "inputs[" << i << "]";
    }
  }
};

std::vector<double> Ramp(int count, double first, double step) {
  std::vector<double> values(count);
  for (int n = 0; n < count; ++n) values[n] = first + step * n;
  return values;
}

void Set(const std::vector<double>& values, google::protobuf::RepeatedField<double>* field) {
  field->Clear();
  field->Add(values.begin(), values.end());
}

v1::PriorUpdate::Entry* AddEntry(google::protobuf::RepeatedPtrField<v1::PriorUpdate::Entry>* entries, int index,
                                 const v1::ComponentPrior& prior) {
  v1::PriorUpdate::Entry* e = entries->Add();
  e->set_index(index);
  *e->mutable_prior() = prior;
  return e;
}

TEST_F(ReconnectFidelityTest, PlainSessionWithPriorUpdatesAndShifts) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  const v1::ProblemSpec spec = SpecOrDie(inst.problem);
  const int N = static_cast<int>(spec.model().horizon());
  std::vector<v1::Step> steps(6);
  for (std::size_t k = 0; k < steps.size(); ++k) {
    const Eigen::VectorXd& x = inst.closed_loop->x1[k];  // measured states of the instance's closed loop
    steps[k].mutable_state()->Add(x.data(), x.data() + x.size());
  }
  // A per-step reference and bound on output 0, then shifted every step.
  v1::ComponentPrior y0 = spec.output_priors(0);
  Set(Ramp(N + 1, -0.5, 0.04), y0.mutable_target());
  Set(Ramp(N + 1, 4.0, -0.05), y0.mutable_upper());
  AddEntry(steps[0].mutable_update()->mutable_outputs(), 0, y0);
  // A per-step input bound and target, in the same step as a shift (entries after it).
  v1::ComponentPrior u1 = spec.input_priors(1);
  Set(Ramp(N, 0.45, -0.01), u1.mutable_upper());
  Set(Ramp(N, 0.1, -0.005), u1.mutable_target());
  steps[1].mutable_update()->set_shift(true);
  AddEntry(steps[1].mutable_update()->mutable_inputs(), 1, u1);
  steps[2].mutable_update()->set_shift(true);
  // A constant reference on output 3 (length 1: unchanged by shifts).
  v1::ComponentPrior y3 = spec.output_priors(3);
  Set({0.3}, y3.mutable_target());
  steps[3].mutable_update()->set_shift(true);
  AddEntry(steps[3].mutable_update()->mutable_outputs(), 3, y3);
  steps[4].clear_state();  // keeps the previous state
  steps[4].mutable_update()->set_shift(true);
  steps[5].mutable_update()->set_shift(true);
  const v1::Step next = steps.back();
  steps.pop_back();
  ExpectSamePlanAfterRestart(spec, steps, next);
}

v1::Matrix ScaledMatrix(const v1::Matrix& m, double scale, double shift) {
  v1::Matrix out = m;
  for (int i = 0; i < out.data_size(); ++i) out.set_data(i, scale * out.data(i) + (i % 5 == 0 ? shift : 0.0));
  return out;
}

TEST_F(ReconnectFidelityTest, PlainSessionWithModelUpdatesAndShifts) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  const v1::ProblemSpec spec = SpecOrDie(inst.problem);
  const int N = static_cast<int>(spec.model().horizon()), M = static_cast<int>(spec.model().num_states());
  const int K = static_cast<int>(spec.model().num_outputs());
  std::vector<v1::Step> steps(6);
  for (std::size_t k = 0; k < steps.size(); ++k) {
    const Eigen::VectorXd& x = inst.closed_loop->x1[k];
    steps[k].mutable_state()->Add(x.data(), x.data() + x.size());
  }
  // A disturbance estimate for every step (stored once), then one step's A and C (the
  // matrices become per-step), a shift with a new last B, per-step offsets, and a shift.
  Set(Ramp(M, -0.02, 0.004), steps[0].mutable_model()->mutable_state_offsets());
  v1::ModelUpdate::MatrixAt* a = steps[1].mutable_model()->add_a();
  a->set_step(2);
  *a->mutable_matrix() = ScaledMatrix(spec.model().a(0), 1.01, 0.002);
  v1::ModelUpdate::MatrixAt* c = steps[1].mutable_model()->add_c();
  c->set_step(N);
  *c->mutable_matrix() = ScaledMatrix(spec.model().c(0), 0.98, 0.0);
  steps[2].mutable_model()->set_shift(true);
  v1::ModelUpdate::MatrixAt* b = steps[2].mutable_model()->add_b();
  b->set_step(N - 1);
  *b->mutable_matrix() = ScaledMatrix(spec.model().b(0), 1.05, 0.001);
  v1::ModelUpdate::VectorAt* d = steps[3].mutable_model()->add_output_offset();
  d->set_step(5);
  Set(Ramp(K, 0.01, 0.001), d->mutable_values());
  v1::ModelUpdate::VectorAt* cx = steps[3].mutable_model()->add_state_offset();
  cx->set_step(N - 1);
  Set(Ramp(M, 0.003, -0.001), cx->mutable_values());
  steps[4].mutable_model()->set_shift(true);
  Set(Ramp(K, -0.01, 0.0), steps[5].mutable_model()->mutable_output_offsets());
  steps[5].mutable_model()->set_shift(true);
  const v1::Step next = steps.back();
  steps.pop_back();
  ExpectSamePlanAfterRestart(spec, steps, next);
}

// A small plant with a per-step rate limit and weighted Δu, and a box on u.
v1::ProblemSpec RateLimitedSpec() {
  constexpr int kN = 15;
  v1::ProblemSpec spec;
  v1::Model* m = spec.mutable_model();
  m->set_num_states(2);
  m->set_num_inputs(1);
  m->set_num_outputs(1);
  m->set_horizon(kN);
  v1::Matrix* a = m->add_a();
  a->set_rows(2);
  a->set_cols(2);
  Set({1.0, 0.1, 0.0, 0.98}, a->mutable_data());
  v1::Matrix* b = m->add_b();
  b->set_rows(2);
  b->set_cols(1);
  Set({0.005, 0.1}, b->mutable_data());
  v1::Matrix* c = m->add_c();
  c->set_rows(1);
  c->set_cols(2);
  Set({1.0, 0.0}, c->mutable_data());
  Set({-0.4, 0.0}, spec.mutable_initial_state()->mutable_mean());
  v1::ComponentPrior* u = spec.add_input_priors();
  u->set_kind(v1::PRIOR_KIND_BOX);
  Set({-0.5}, u->mutable_lower());
  Set({0.5}, u->mutable_upper());
  Set({10.0}, u->mutable_weight());
  Set(Ramp(kN, 0.2, 0.01), u->mutable_target());
  v1::ComponentPrior* y = spec.add_output_priors();
  Set({50.0}, y->mutable_weight());
  Set({1.0}, y->mutable_target());
  v1::InputDifferences* d = spec.mutable_input_differences();
  v1::ComponentPrior* du = d->add_priors();
  du->set_kind(v1::PRIOR_KIND_BOX);
  Set(Ramp(kN, -0.04, -0.002), du->mutable_lower());
  Set(Ramp(kN, 0.04, 0.002), du->mutable_upper());
  Set(Ramp(kN, 1.0, 0.1), du->mutable_weight());
  Set({0.1}, d->mutable_previous_input());
  return spec;
}

// Steps with shifts, a per-step reference, and one step with its own previous_input.
std::vector<v1::Step> RateLimitedSteps(const v1::ProblemSpec& spec) {
  std::vector<v1::Step> steps(5);
  for (std::size_t k = 0; k < steps.size(); ++k) {
    Set({-0.4 + 0.03 * static_cast<double>(k), 0.02 * static_cast<double>(k)}, steps[k].mutable_state());
    steps[k].mutable_update()->set_shift(true);
  }
  steps[2].add_previous_input(0.05);  // this step's u[-1] only; the next carries its plan's u[0]
  v1::ComponentPrior y = spec.output_priors(0);
  Set(Ramp(16, 0.8, 0.01), y.mutable_target());
  AddEntry(steps[3].mutable_update()->mutable_outputs(), 0, y);
  return steps;
}

TEST_F(ReconnectFidelityTest, InputDifferenceSessionKeepsTheAppliedInputAndShiftedRates) {
  const v1::ProblemSpec spec = RateLimitedSpec();
  std::vector<v1::Step> steps = RateLimitedSteps(spec);
  const v1::Step next = steps.back();  // u[-1]: the last plan's u[0]
  steps.pop_back();
  ExpectSamePlanAfterRestart(spec, steps, next);
}

// A shift on a Δu session moves the priors on u[0..N-1] and leaves the fixed u[-1] free
// (core::InputMappedSession): the re-created session, whose resent step does not shift,
// then equals the one that never restarted.
TEST_F(ReconnectFidelityTest, InputDifferenceSessionResentStepWithoutShift) {
  const v1::ProblemSpec spec = RateLimitedSpec();
  std::vector<v1::Step> steps = RateLimitedSteps(spec);
  v1::Step next = steps.back();
  next.clear_update();
  steps.pop_back();
  ExpectSamePlanAfterRestart(spec, steps, next);
}

// The example of [Nghiem] §V (x[k] = x[k-1] - 0.5 tanh(x[k-1] + u[k]³)) as a GP session on
// a logged experiment with a fixed kernel; the window is [y[t-1], u[t-1]].
v1::ProblemSpec GpSpec() {
  v1::ProblemSpec spec;
  v1::GpMpc* g = spec.mutable_gp();
  v1::GpModel* model = g->mutable_model();
  model->set_output_lags(1);
  model->set_input_lags(0);
  double x = 0.0;
  for (int k = 0; k < 120; ++k) {
    const double u = std::sin(0.37 * k) * std::cos(0.11 * k);  // a deterministic excitation
    x = x - 0.5 * std::tanh(x + u * u * u);
    model->add_logged_inputs(u);
    model->add_logged_outputs(x + 0.01 * std::sin(1.7 * k));
  }
  v1::GpKernel* kernel = model->mutable_kernel();
  kernel->set_signal_variance(1.0);
  kernel->add_length_scales(1.0);
  kernel->add_length_scales(1.0);
  kernel->set_noise_variance(1e-3);
  g->set_horizon(8);
  g->set_output_weight(10.0);
  g->set_input_change_weight(0.1);
  g->set_input_min(-1.0);
  g->set_input_max(1.0);
  g->set_rate_min(-0.5);
  g->set_rate_max(0.5);
  g->set_output_min(-1.2);
  g->set_output_max(1.2);
  g->set_sigma_multiple(2.0);
  g->add_reference(-0.5);
  return spec;
}

TEST_F(ReconnectFidelityTest, GpSessionKeepsItsLatestReference) {
  const v1::ProblemSpec spec = GpSpec();
  const int H = static_cast<int>(spec.gp().horizon());
  std::vector<v1::Step> steps(4);
  for (std::size_t k = 0; k < steps.size(); ++k) {
    Set({-0.1 * static_cast<double>(k), 0.05 * static_cast<double>(k)}, steps[k].mutable_state());
  }
  steps[1].add_reference(-0.3);                            // constant
  Set(Ramp(H, -0.3, 0.02), steps[2].mutable_reference());  // per step; kept by the next steps
  const v1::Step next = steps.back();
  steps.pop_back();
  ExpectSamePlanAfterRestart(spec, steps, next);
}

}  // namespace
}  // namespace nupmpc::testing
