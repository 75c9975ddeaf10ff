// Numerical hostility that passes validation: ill-conditioned models,
// bounds 1e-300 and 1e300 wide, contradictory output bounds, a state the inputs cannot
// bring inside its bounds, tiny time limits and a cap of one pass. Every answer is
// finite wherever it describes a plan, its status is the honest one for the case, and
// the session (and the server) goes on solving a feasible step exactly as a fresh one.
#include <cmath>
#include <cstdio>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using Statuses = std::set<v1::SolveStatus>;
constexpr int kMasses = 12;  // masses_N30: 12 states = 12 outputs (C = I), 3 inputs

// The masses_N30 problem on another horizon: every step's priors those of step 1.
core::Problem MassesOnHorizon(const core::Problem& masses, int horizon) {
  core::Problem p = core::Problem::TimeInvariant(masses.num_states, masses.num_inputs, masses.num_outputs, horizon);
  p.A = masses.A;
  p.B = masses.B;
  p.C = masses.C;
  p.initial_mean = masses.initial_mean;
  p.terminal = masses.terminal;
  for (int n = 0; n < horizon; ++n) {
    for (int l = 0; l < p.num_inputs; ++l) p.mutable_input_prior(n, l) = masses.input_prior(1, l);
  }
  for (int n = 1; n <= horizon; ++n) {
    for (int k = 0; k < p.num_outputs; ++k) p.mutable_output_prior(n, k) = masses.output_prior(1, k);
  }
  return p;
}

// Every output or input prior of the problem becomes the box [lower, upper] (the Gaussian
// part kept).
void SetBoxes(std::vector<core::ScalarPrior>* priors, double lower, double upper) {
  for (core::ScalarPrior& prior : *priors) {
    if (prior.kind == core::PriorKind::kBox) prior.lower = lower, prior.upper = upper;
  }
}

struct SpecCase {
  const char* name;
  std::function<core::Problem(const core::Problem& masses)> problem;
  Statuses honest;  // the statuses that are honest for it
};

std::vector<SpecCase> SpecCases() {
  const Statuses infeasible = {v1::SOLVE_STATUS_INFEASIBLE};
  return {
      {"A scaled to spectral radius 1e3, N = 1000",
       [](const core::Problem& m) {
         core::Problem p = MassesOnHorizon(m, 1000);
         p.A[0] *= 1e3;  // masses' A is marginally stable: spectral radius 1
         return p;
       },
       {v1::SOLVE_STATUS_INFEASIBLE, v1::SOLVE_STATUS_NUMERICAL_ERROR}},
      // Not found by the multipliers (they stay bounded while γ = 5e-301): the solve runs
      // to its cap, and says so.
      {"output boxes 1e-300 wide",
       [](const core::Problem& m) {
         core::Problem p = m;
         SetBoxes(&p.output_priors, 0.0, 1e-300);
         return p;
       },
       {v1::SOLVE_STATUS_INFEASIBLE, v1::SOLVE_STATUS_ITERATION_LIMIT}},
      {"input boxes 1e-300 wide",
       [](const core::Problem& m) {
         core::Problem p = m;
         SetBoxes(&p.input_priors, 0.0, 1e-300);
         return p;
       },
       infeasible},
      {"output boxes 1e300 wide",
       [](const core::Problem& m) {
         core::Problem p = m;
         SetBoxes(&p.output_priors, -1e300, 1e300);
         return p;
       },
       {v1::SOLVE_STATUS_CONVERGED}},
      {"input boxes 1e300 wide",
       [](const core::Problem& m) {
         core::Problem p = m;
         SetBoxes(&p.input_priors, -1e300, 1e300);
         return p;
       },
       {v1::SOLVE_STATUS_CONVERGED}},
      {"an output's lower bound above what the inputs can reach",
       [](const core::Problem& m) {
         core::Problem p = m;
         for (int n = 1; n <= p.horizon; ++n)
           p.mutable_output_prior(n, 0).lower = 3.0, p.mutable_output_prior(n, 0).upper = 4.0;
         return p;
       },
       infeasible},
      {"two outputs of the same state with disjoint boxes",
       [](const core::Problem& m) {
         core::Problem p = core::Problem::TimeInvariant(m.num_states, m.num_inputs, m.num_outputs + 1, m.horizon);
         p.A = m.A;
         p.B = m.B;
         p.C[0].topRows(m.num_outputs) = m.C[0];
         p.C[0].row(m.num_outputs) = m.C[0].row(0);  // output 12 measures position 1 again
         p.initial_mean = m.initial_mean;
         p.terminal = m.terminal;
         p.input_priors = m.input_priors;
         for (int n = 1; n <= p.horizon; ++n) {
           for (int k = 0; k < m.num_outputs; ++k) p.mutable_output_prior(n, k) = m.output_prior(n, k);
           p.mutable_output_prior(n, 0) = core::ScalarPrior::Box(1.0, 2.0).WithGaussian(0.0, 1.0);
           p.mutable_output_prior(n, m.num_outputs) = core::ScalarPrior::Box(-2.0, -1.0).WithGaussian(0.0, 1.0);
         }
         return p;
       },
       infeasible},
  };
}

class HostileSolvesTest : public ServiceTest {
 protected:
  void SetUp() override {
    ServiceTest::SetUp();
    instance_ = LoadInstanceOrDie("masses_N30");
    spec_ = SpecOrDie(instance_.problem);
  }
  v1::Step StateStep(int t, v1::WarmStart warm = v1::WARM_START_COLD) const {
    v1::Step step;
    const Eigen::VectorXd& x = instance_.closed_loop->x1[t];
    step.mutable_state()->Add(x.data(), x.data() + x.size());
    step.set_warm_start(warm);
    return step;
  }
  // Whatever the status: no NaN or infinity in anything that describes a plan, and no plan
  // values without has_plan.
  static void ExpectHonestNumbers(const v1::SolveResult& r) {
    for (double v : r.inputs()) ASSERT_TRUE(std::isfinite(v));
    for (double v : r.states()) ASSERT_TRUE(std::isfinite(v));
    for (double v : r.outputs()) ASSERT_TRUE(std::isfinite(v));
    if (r.has_plan()) {
      EXPECT_TRUE(std::isfinite(r.objective()));
      EXPECT_TRUE(std::isfinite(r.max_violation()));
      EXPECT_GT(r.inputs_size(), 0);
    } else {
      EXPECT_EQ(r.inputs_size(), 0);
      EXPECT_EQ(r.states_size(), 0);
    }
  }
  static void Print(const char* name, const v1::SolveResult& r) {
    std::printf("%-58s %-30s it %5u  J %-12.6g viol %-12.6g plan %d\n", name, v1::SolveStatus_Name(r.status()).c_str(),
                r.iterations(), r.objective(), r.max_violation(), r.has_plan());
  }
  // A session that solved a hostile step on masses_N30 answers a feasible state as a fresh
  // session does, cold and warm, to the solver's tolerance (not bit for bit: after an
  // exploded solve the cold plan differs from a fresh session's in the last digits).
  void ExpectSessionUsable(const std::string& id) {
    auto fresh = client_->CreateSession(spec_);
    ASSERT_TRUE(fresh.ok());
    auto reference = client_->Solve(fresh->session_id(), StateStep(7));
    ASSERT_TRUE(reference.ok());
    ASSERT_EQ(reference->status(), v1::SOLVE_STATUS_CONVERGED);
    auto cold = client_->Solve(id, StateStep(7));
    ASSERT_TRUE(cold.ok()) << cold.status();
    EXPECT_EQ(cold->status(), v1::SOLVE_STATUS_CONVERGED);
    EXPECT_NEAR(cold->objective(), reference->objective(), 1e-9 * std::abs(reference->objective()));
    ASSERT_EQ(cold->inputs_size(), reference->inputs_size());
    for (int i = 0; i < cold->inputs_size(); ++i) EXPECT_NEAR(cold->inputs(i), reference->inputs(i), 1e-7) << i;
    auto warm = client_->Solve(id, StateStep(7, v1::WARM_START_KEEP));
    ASSERT_TRUE(warm.ok()) << warm.status();
    EXPECT_EQ(warm->status(), v1::SOLVE_STATUS_CONVERGED);
    EXPECT_NEAR(warm->objective(), reference->objective(), 1e-9 * std::abs(reference->objective()));
    ASSERT_TRUE(client_->CloseSession(fresh->session_id()).ok());
  }

  bench::BenchmarkInstance instance_;
  v1::ProblemSpec spec_;
};

TEST_F(HostileSolvesTest, HostileSpecsGetFiniteAnswersAndHonestStatuses) {
  auto healthy = client_->CreateSession(spec_);
  ASSERT_TRUE(healthy.ok());
  auto healthy_before = client_->Solve(healthy->session_id(), StateStep(4));
  ASSERT_TRUE(healthy_before.ok());
  for (const SpecCase& c : SpecCases()) {
    SCOPED_TRACE(c.name);
    const v1::ProblemSpec spec = SpecOrDie(c.problem(instance_.problem));
    absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
    ASSERT_TRUE(once.ok()) << once.status();
    Print(c.name, *once);
    ExpectHonestNumbers(*once);
    EXPECT_THAT(c.honest, ::testing::Contains(once->status())) << v1::SolveStatus_Name(once->status());
    if (once->status() == v1::SOLVE_STATUS_INFEASIBLE) {
      EXPECT_TRUE(once->has_plan());
      EXPECT_GT(once->max_violation(), 0.0);
      EXPECT_LT(once->iterations(), 2500u) << "found by its multipliers, not by the cap of 5000";
    }
    // A session of the same spec answers the same, and again cold: nothing left over from
    // the hostile solve changes the next one.
    auto session = client_->CreateSession(spec);
    ASSERT_TRUE(session.ok()) << session.status();
    for (int repeat = 0; repeat < 2; ++repeat) {
      v1::Step step;
      step.set_warm_start(v1::WARM_START_COLD);
      auto again = client_->Solve(session->session_id(), step);
      ASSERT_TRUE(again.ok()) << again.status();
      ExpectHonestNumbers(*again);
      EXPECT_EQ(again->status(), once->status());
      if (once->has_plan() && once->status() != v1::SOLVE_STATUS_CONVERGED) {
        EXPECT_EQ(again->objective(), once->objective());
      }
    }
    ASSERT_TRUE(client_->CloseSession(session->session_id()).ok());
  }
  auto healthy_after = client_->Solve(healthy->session_id(), StateStep(4));
  ASSERT_TRUE(healthy_after.ok());
  EXPECT_EQ(healthy_after->objective(), healthy_before->objective());
}

struct StepCase {
  const char* name;
  std::function<void(v1::Step*)> set;
  Statuses honest;
  bool needs_plan = false;  // the status promises a plan (proto: SolveResult)
};

std::vector<StepCase> StepCases() {
  return {
      {"every state at 3.9 (the bound 4 cannot be kept)",
       [](v1::Step* s) {
         for (int i = 0; i < kMasses; ++i) s->set_state(i, 3.9);
       },
       {v1::SOLVE_STATUS_INFEASIBLE},
       true},
      {"position 1 at 3.99, velocity 1 at 3.9 (barely out of reach)",
       [](v1::Step* s) {
         s->set_state(0, 3.99);
         s->set_state(6, 3.9);
       },
       {v1::SOLVE_STATUS_INFEASIBLE},
       true},
      {"time_limit_ms = 1e-6", [](v1::Step* s) { s->set_time_limit_ms(1e-6); }, {v1::SOLVE_STATUS_TIME_LIMIT}},
      {"time_limit_ms = 1e-3",
       [](v1::Step* s) { s->set_time_limit_ms(1e-3); },
       {v1::SOLVE_STATUS_TIME_LIMIT, v1::SOLVE_STATUS_CONVERGED}},
      {"max_iterations = 1",
       [](v1::Step* s) { s->set_max_iterations(1); },
       {v1::SOLVE_STATUS_ITERATION_LIMIT, v1::SOLVE_STATUS_CONVERGED},
       true},
      {"infeasible state, max_iterations = 1",
       [](v1::Step* s) {
         for (int i = 0; i < kMasses; ++i) s->set_state(i, 3.9);
         s->set_max_iterations(1);
       },
       {v1::SOLVE_STATUS_ITERATION_LIMIT},
       true},
      {"infeasible state, time_limit_ms = 1e-3",
       [](v1::Step* s) {
         for (int i = 0; i < kMasses; ++i) s->set_state(i, 3.9);
         s->set_time_limit_ms(1e-3);
       },
       {v1::SOLVE_STATUS_TIME_LIMIT, v1::SOLVE_STATUS_INFEASIBLE}},
  };
}

TEST_F(HostileSolvesTest, HostileStepsGetHonestStatusesAndLeaveTheSessionUsable) {
  for (const StepCase& c : StepCases()) {
    SCOPED_TRACE(c.name);
    auto created = client_->CreateSession(spec_);
    ASSERT_TRUE(created.ok());
    const std::string id = created->session_id();
    ASSERT_TRUE(client_->Solve(id, StateStep(4, v1::WARM_START_KEEP)).ok());  // a warm start to disturb
    v1::Step step = StateStep(4, v1::WARM_START_KEEP);
    c.set(&step);
    absl::StatusOr<v1::SolveResult> r = client_->Solve(id, step);
    ASSERT_TRUE(r.ok()) << r.status();
    Print(c.name, *r);
    ExpectHonestNumbers(*r);
    EXPECT_THAT(c.honest, ::testing::Contains(r->status())) << v1::SolveStatus_Name(r->status());
    if (c.needs_plan) {
      EXPECT_TRUE(r->has_plan());
    }
    if (r->status() == v1::SOLVE_STATUS_INFEASIBLE) {
      EXPECT_GT(r->max_violation(), 0.0);
      EXPECT_LT(r->iterations(), 500u) << "found by its multipliers, not by the cap of 5000";
    }
    ExpectSessionUsable(id);
    ASSERT_TRUE(client_->CloseSession(id).ok());
  }
}

}  // namespace
}  // namespace nupmpc::testing
