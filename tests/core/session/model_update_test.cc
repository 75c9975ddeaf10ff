// StepUpdate.model (core/session/model_update.h): new model terms change a session exactly
// as a session created with the same (time-varying) problem solves it; a time-invariant
// matrix given for one step becomes per-step; a rejected update names its field and
// leaves the session bit-identical; the warm start carries over small model changes.
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/core_session.h"
#include "tests/util/random_problem.h"

namespace nupmpc::core {
namespace {

using nupmpc::testing::MakeSession;
using nupmpc::testing::Plan;

using ::testing::HasSubstr;

Problem BoxedProblem() {
  nupmpc::testing::RandomProblemSpec spec;
  spec.M = 4;
  spec.L = 2;
  spec.K = 3;
  spec.N = 15;
  spec.seed = 11;
  Problem p = nupmpc::testing::WithBoxes(nupmpc::testing::RandomGaussianProblem(spec), 0.8, 0.0);
  // Time-invariant, as most sessions are created.
  p.A.resize(1);
  p.B.resize(1);
  p.C.resize(1);
  p.state_offset.clear();
  p.output_offset.clear();
  return p;
}

Plan SolveOnce(Session& session, bool warm) {
  SolveLimits limits;
  limits.warm_start = warm;
  Solution solution;
  absl::StatusOr<SolveSummary> summary = session.Solve(limits, &solution);
  EXPECT_TRUE(summary.ok() && summary->has_plan) << summary.status();
  EXPECT_EQ(summary->status, SolveStatus::kConverged);
  if (!summary.ok()) return {};
  return {solution.inputs, summary->objective, summary->iterations};
}
void ExpectSamePlan(const Plan& a, const Plan& b, double tolerance) {
  ASSERT_EQ(a.inputs.rows(), b.inputs.rows());
  ASSERT_EQ(a.inputs.cols(), b.inputs.cols());
  EXPECT_LE((a.inputs - b.inputs).cwiseAbs().maxCoeff(), tolerance);
  EXPECT_NEAR(a.objective, b.objective, tolerance * std::max(1.0, std::abs(b.objective)));
}

// A deterministic perturbation of `m` that differs per step.
Eigen::MatrixXd Perturbed(const Eigen::MatrixXd& m, int step, double size) {
  Eigen::MatrixXd out = m;
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) out(i, j) += size * std::sin(1.0 + step + 3.0 * i + 7.0 * j);
  }
  return out;
}

// Every A, B, C and offset per step, as a linearised nonlinear plant would send.
ModelChanges FullLtvChanges(const Problem& p, double size) {
  ModelChanges m;
  const int N = p.horizon;
  for (int n = 0; n < N; ++n) {
    m.A.push_back({n, Perturbed(p.A_at(n), n, size)});
    m.B.push_back({n, Perturbed(p.B_at(n), n + 50, size)});
    m.state_offset.push_back({n, Eigen::VectorXd::Constant(p.num_states, size * std::cos(n))});
  }
  for (int n = 0; n <= N; ++n) {
    m.C.push_back({n, Perturbed(p.C_at(n), n + 100, size)});
    m.output_offset.push_back({n, Eigen::VectorXd::Constant(p.num_outputs, size * std::sin(n))});
  }
  return m;
}

// `p` with the changes written out by hand (the reference the session is compared with).
Problem WrittenOut(const Problem& p, const ModelChanges& m) {
  Problem q = p;
  const int N = p.horizon;
  const auto per_step = [](std::vector<Eigen::MatrixXd>* v, int steps) {
    if (static_cast<int>(v->size()) != steps) v->assign(steps, v->front());
  };
  if (!m.A.empty()) per_step(&q.A, N);
  if (!m.B.empty()) per_step(&q.B, N);
  if (!m.C.empty()) per_step(&q.C, N + 1);
  for (const auto& e : m.A) q.A[e.step] = e.value;
  for (const auto& e : m.B) q.B[e.step] = e.value;
  for (const auto& e : m.C) q.C[e.step] = e.value;
  if (!m.state_offset.empty()) {
    std::vector<Eigen::VectorXd> c(N);
    for (int n = 0; n < N; ++n) {
      c[n] = Eigen::VectorXd::Zero(p.num_states);
      for (int i = 0; i < p.num_states; ++i) c[n](i) = p.state_offset_at(n, i);
    }
    for (const auto& e : m.state_offset) c[e.step] = e.value;
    q.state_offset = c;
  }
  if (!m.output_offset.empty()) {
    std::vector<Eigen::VectorXd> d(N + 1);
    for (int n = 0; n <= N; ++n) {
      d[n] = Eigen::VectorXd::Zero(p.num_outputs);
      for (int k = 0; k < p.num_outputs; ++k) d[n](k) = p.output_offset_at(n, k);
    }
    for (const auto& e : m.output_offset) d[e.step] = e.value;
    q.output_offset = d;
  }
  return q;
}

TEST(ModelUpdate, ATimeVaryingModelSolvesAsASessionCreatedWithIt) {
  const Problem base = BoxedProblem();
  std::unique_ptr<Session> session = MakeSession(base);
  ASSERT_TRUE(session);
  SolveOnce(*session, /*warm=*/false);

  StepUpdate update;
  update.model = FullLtvChanges(base, 0.05);
  ASSERT_TRUE(session->Apply(update).ok());
  const Problem expected = WrittenOut(base, update.model);
  EXPECT_EQ(session->problem().A.size(), static_cast<std::size_t>(base.horizon));
  EXPECT_EQ(session->problem().C.size(), static_cast<std::size_t>(base.horizon + 1));
  for (int n = 0; n < base.horizon; ++n) {
    EXPECT_EQ(session->problem().A[n], expected.A[n]);
    EXPECT_EQ(session->problem().B[n], expected.B[n]);
  }

  std::unique_ptr<Session> created = MakeSession(expected);
  ASSERT_TRUE(created);
  ExpectSamePlan(SolveOnce(*session, /*warm=*/false), SolveOnce(*created, /*warm=*/false), 1e-9);
}

TEST(ModelUpdate, OneStepOfATimeInvariantMatrixMakesItPerStepAndKeepsTheOthers) {
  const Problem base = BoxedProblem();
  std::unique_ptr<Session> session = MakeSession(base);
  ASSERT_TRUE(session);
  StepUpdate update;
  update.model.A.push_back({3, Perturbed(base.A[0], 3, 0.1)});
  ASSERT_TRUE(session->Apply(update).ok());
  const Problem& p = session->problem();
  ASSERT_EQ(p.A.size(), static_cast<std::size_t>(base.horizon));
  for (int n = 0; n < base.horizon; ++n) EXPECT_EQ(p.A[n], n == 3 ? update.model.A[0].value : base.A[0]) << n;
  EXPECT_EQ(p.B.size(), 1u);  // untouched terms keep their storage
  std::unique_ptr<Session> created = MakeSession(WrittenOut(base, update.model));
  ExpectSamePlan(SolveOnce(*session, false), SolveOnce(*created, false), 1e-9);
}

TEST(ModelUpdate, ShiftMovesEveryPerStepTermOneStepEarlierThenTheEntriesApply) {
  Problem base = BoxedProblem();
  base = WrittenOut(base, FullLtvChanges(base, 0.05));  // created time-varying
  const int N = base.horizon;
  std::unique_ptr<Session> session = MakeSession(base);
  ASSERT_TRUE(session);
  StepUpdate update;
  update.model.shift = true;
  update.model.A.push_back({N - 1, Perturbed(base.A[N - 1], 99, 0.02)});
  ASSERT_TRUE(session->Apply(update).ok());
  const Problem& p = session->problem();
  for (int n = 0; n + 2 < N; ++n) EXPECT_EQ(p.A[n], base.A[n + 1]) << n;
  EXPECT_EQ(p.A[N - 1], update.model.A[0].value);
  for (int n = 0; n + 1 < N; ++n) {
    EXPECT_EQ(p.B[n], base.B[n + 1]) << n;
    EXPECT_EQ(p.state_offset[n], base.state_offset[n + 1]) << n;
  }
  EXPECT_EQ(p.B[N - 1], base.B[N - 1]);  // the last step repeated
  for (int n = 0; n < N; ++n) EXPECT_EQ(p.C[n], base.C[n + 1]) << n;
  EXPECT_EQ(p.C[N], base.C[N]);
}

TEST(ModelUpdate, AllStepOffsetsKeepTheStorageAndTheWarmStart) {
  const Problem base = BoxedProblem();
  std::unique_ptr<Session> session = MakeSession(base);
  ASSERT_TRUE(session);
  SolveOnce(*session, false);
  ASSERT_TRUE(session->has_warm_start());
  StepUpdate update;
  update.model.state_offsets = Eigen::VectorXd::Constant(base.num_states, 0.02);
  update.model.output_offsets = Eigen::VectorXd::LinSpaced(base.num_outputs * (base.horizon + 1), -0.1, 0.1);
  ASSERT_TRUE(session->Apply(update).ok());
  EXPECT_TRUE(session->has_warm_start());
  EXPECT_EQ(session->problem().A.size(), 1u);
  ASSERT_EQ(session->problem().state_offset.size(), 1u);
  ASSERT_EQ(session->problem().output_offset.size(), static_cast<std::size_t>(base.horizon + 1));
  EXPECT_EQ(session->problem().output_offset_at(2, 1), update.model.output_offsets->coeff(2 * base.num_outputs + 1));

  Problem expected = base;
  expected.state_offset = {*update.model.state_offsets};
  expected.output_offset.clear();
  for (int n = 0; n <= base.horizon; ++n) {
    expected.output_offset.push_back(update.model.output_offsets->segment(n * base.num_outputs, base.num_outputs));
  }
  std::unique_ptr<Session> created = MakeSession(expected);
  ExpectSamePlan(SolveOnce(*session, /*warm=*/true), SolveOnce(*created, false), 1e-8);
}

TEST(ModelUpdate, TheWarmStartCarriesOverASmallModelChange) {
  Problem base = BoxedProblem();
  base = WrittenOut(base, FullLtvChanges(base, 0.05));
  std::unique_ptr<Session> session = MakeSession(base);
  ASSERT_TRUE(session);
  SolveOnce(*session, false);
  // The next period's linearisation: the model moves by 1 % of its entries.
  StepUpdate update;
  update.model = FullLtvChanges(base, 0.005);
  ASSERT_TRUE(session->Apply(update).ok());
  EXPECT_TRUE(session->has_warm_start());
  const Plan warm = SolveOnce(*session, /*warm=*/true);
  std::unique_ptr<Session> cold_twin = MakeSession(session->problem());
  const Plan cold = SolveOnce(*cold_twin, /*warm=*/false);
  ExpectSamePlan(warm, cold, 1e-7);
  EXPECT_LT(warm.iterations, cold.iterations) << "warm " << warm.iterations << ", cold " << cold.iterations;
}

struct Rejected {
  const char* name;
  ModelChanges (*make)(const Problem&);
  const char* field;
};

TEST(ModelUpdate, ARejectedUpdateNamesItsFieldAndLeavesTheSessionBitIdentical) {
  const Problem base = BoxedProblem();
  const std::vector<Rejected> cases = {
      {"step out of range",
       [](const Problem& p) {
         ModelChanges m;
         m.A.push_back({p.horizon, p.A[0]});
         return m;
       },
       "model.a[0].step = 15: must be < horizon = 15"},
      {"wrong matrix size",
       [](const Problem& p) {
         ModelChanges m;
         m.B.push_back({0, p.A[0]});
         return m;
       },
       "model.b[0].matrix: expected 4x2, got 4x4"},
      {"non-finite",
       [](const Problem& p) {
         ModelChanges m;
         m.C.push_back({1, p.C[0]});
         m.C[0].value(0, 0) = std::numeric_limits<double>::infinity();
         return m;
       },
       "model.c[0].matrix: contains a non-finite number"},
      {"step given twice",
       [](const Problem& p) {
         ModelChanges m;
         m.A.push_back({2, p.A[0]});
         m.A.push_back({2, p.A[0]});
         return m;
       },
       "model.a[1].step = 2: that step is given twice"},
      {"offsets of the wrong length",
       [](const Problem& p) {
         ModelChanges m;
         m.state_offsets = Eigen::VectorXd::Zero(p.num_states + 1);
         return m;
       },
       "model.state_offsets: expected 4 values (every step) or 60"},
      {"a good change next to a bad one",
       [](const Problem& p) {
         ModelChanges m = FullLtvChanges(p, 0.05);
         m.output_offset.back().value.resize(1);
         return m;
       },
       "model.output_offset[15].values: expected 3 values, got 1"},
  };
  for (const Rejected& c : cases) {
    SCOPED_TRACE(c.name);
    std::unique_ptr<Session> session = MakeSession(base), twin = MakeSession(base);
    ASSERT_TRUE(session && twin);
    SolveOnce(*session, false);
    SolveOnce(*twin, false);
    StepUpdate bad;
    bad.state = Eigen::VectorXd::Constant(base.num_states, 0.4);
    bad.model = c.make(base);
    const absl::Status status = session->Apply(bad);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(status.message()), HasSubstr(c.field));
    EXPECT_EQ(session->problem().A.size(), base.A.size());
    EXPECT_EQ(session->problem().A[0], base.A[0]);
    EXPECT_EQ(session->problem().initial_mean, base.initial_mean);  // the state was not taken either
    EXPECT_TRUE(session->problem().state_offset.size() == base.state_offset.size());
    const Plan after = SolveOnce(*session, true), twins = SolveOnce(*twin, true);
    EXPECT_TRUE(after.inputs == twins.inputs);
    EXPECT_EQ(after.iterations, twins.iterations);
  }
}

}  // namespace
}  // namespace nupmpc::core
