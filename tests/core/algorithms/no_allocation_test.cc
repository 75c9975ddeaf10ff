// Nothing is heap-allocated inside the iteration loop (issue: memory). Every malloc of the
// process is counted (Eigen allocates with malloc, not operator new, so counting new alone
// would miss it). A solve's allocations must not depend on how many iterations it runs:
// in fact a whole solve (without copying out a Solution) allocates nothing.
#include <dlfcn.h>

#include <atomic>
#include <cstdlib>
#include <cstring>

#include "core/examples/scenarios/dac.h"
#include "core/session/session.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"
#include "tests/util/test_names.h"

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

extern "C" {
extern void* __libc_malloc(size_t);
extern void* __libc_calloc(size_t, size_t);
extern void* __libc_realloc(void*, size_t);
extern void* __libc_memalign(size_t, size_t);
void* malloc(size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n);
}
void* calloc(size_t a, size_t b) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_calloc(a, b);
}
void* realloc(void* p, size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_realloc(p, n);
}
int posix_memalign(void** out, size_t alignment, size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  *out = __libc_memalign(alignment, n);
  return *out == nullptr ? 12 /*ENOMEM*/ : 0;
}
void* aligned_alloc(size_t alignment, size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_memalign(alignment, n);
}
}

namespace nupmpc::core {
namespace {

const std::string kDir = NUPMPC_BENCHMARK_DIR;

long AllocationsDuringSolve(Session& session, int max_iterations, bool warm) {
  SolveLimits limits;
  limits.max_iterations = max_iterations;
  limits.warm_start = warm;
  const long before = g_allocations.load();
  absl::StatusOr<SolveSummary> s = session.Solve(limits, nullptr);
  const long after = g_allocations.load();
  EXPECT_TRUE(s.ok());
  EXPECT_EQ(s->iterations, max_iterations) << s->Describe();
  return after - before;
}

TEST(NoAllocation, CountingMallocSeesTheTestsOwnAllocations) {
  const long before = g_allocations.load();
  Eigen::MatrixXd m(20, 20);
  m.setZero();
  EXPECT_GT(g_allocations.load(), before);
}

class NoAllocationInLoop : public ::testing::TestWithParam<std::pair<const char*, Algorithm>> {};

TEST_P(NoAllocationInLoop, AllocationsDoNotGrowWithIterations) {
  const auto [name, algorithm] = GetParam();
  auto inst = bench::LoadBenchmarkInstance(kDir + "/" + name + ".json");
  ASSERT_TRUE(inst.ok()) << inst.status();
  SolverOptions options;
  options.algorithm = algorithm;
  options.polish_after_stable_iterations = 0;  // fixed iteration counts below
  options.objective_tolerance = 1e-300;        // never converge early
  options.violation_tolerance = 1e-300;
  auto session = Session::Create(inst->problem, options);
  ASSERT_TRUE(session.ok()) << session.status();
  (void)AllocationsDuringSolve(**session, 2, false);  // first call warms up lazily built state
  const long short_solve = AllocationsDuringSolve(**session, 2, false);
  const long long_solve = AllocationsDuringSolve(**session, 40, false);
  const long warm_solve = AllocationsDuringSolve(**session, 40, true);
  EXPECT_EQ(long_solve, short_solve) << "allocations grow with the iteration count";
  EXPECT_EQ(warm_solve, short_solve);
  EXPECT_EQ(short_solve, 0);
}

TEST(NoAllocation, PolishAndShiftDoNotAllocateEither) {
  auto inst = bench::LoadBenchmarkInstance(kDir + "/masses_N30.json");
  ASSERT_TRUE(inst.ok());
  auto session = Session::Create(inst->problem);
  ASSERT_TRUE(session.ok());
  ASSERT_TRUE((*session)->Solve(nullptr).ok());
  const Eigen::VectorXd x0 = inst->problem.initial_mean * 0.9;
  const long before = g_allocations.load();
  (*session)->ShiftWarmStart();
  ASSERT_TRUE((*session)->SetInitialState(x0).ok());
  const long after_update = g_allocations.load();
  EXPECT_EQ(after_update, before);
  auto s = (*session)->Solve(nullptr);
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(s->polished);
  EXPECT_EQ(g_allocations.load() - after_update, 0);
}

TEST(NoAllocation, BinaryFixingAndSearchDoNotAllocate) {
  // Binary inputs end with the fixing passes (pins) and the discrete local search.
  auto session = Session::Create(examples::DacWindow(60, 0.01, 0, 2.0));
  ASSERT_TRUE(session.ok());
  SolveLimits limits;
  limits.max_iterations = 5;
  ASSERT_TRUE((*session)->Solve(limits, nullptr).ok());  // warms up lazily built state
  for (const int iterations : {5, 200}) {
    limits.max_iterations = iterations;
    const long before = g_allocations.load();
    auto s = (*session)->Solve(limits, nullptr);
    const long allocated = g_allocations.load() - before;
    ASSERT_TRUE(s.ok());
    EXPECT_TRUE(s->rounded);
    EXPECT_GT(s->iterations, iterations);  // the fixing passes ran
    EXPECT_EQ(allocated, 0) << iterations << " iterations";
  }
}

TEST(NoAllocation, TheElasticFallbackDoesNotAllocate) {
  // masses_N30 with its position bounds tightened to ±0.05 around a start far outside
  // them: infeasible, so every solve switches to the elastic form and back.
  auto inst = bench::LoadBenchmarkInstance(kDir + "/masses_N30.json");
  ASSERT_TRUE(inst.ok());
  Problem p = inst->problem;
  for (ScalarPrior& prior : p.output_priors) {
    if (prior.kind == PriorKind::kBox && prior.is_hard()) prior = ScalarPrior::Box(-0.05, 0.05);
  }
  p.initial_mean = Eigen::VectorXd::Constant(p.num_states, 3.0);
  SolverOptions options;
  options.elastic_slope = 1e3;
  options.elastic_after_iterations = 20;
  auto session = Session::Create(p, options);
  ASSERT_TRUE(session.ok()) << session.status();
  ASSERT_TRUE((*session)->Solve(nullptr).ok());  // warms up lazily built state
  const long before = g_allocations.load();
  auto s = (*session)->Solve(nullptr);
  const long allocated = g_allocations.load() - before;
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(s->elastic);
  EXPECT_EQ(s->status, SolveStatus::kInfeasible) << s->Describe();
  EXPECT_EQ(allocated, 0);
}

// The interior-point iteration of a cold IFFBDD solve (hard output bounds only), its
// corrector passes and the polish after it.
TEST(NoAllocation, InteriorPointSolvesDoNotAllocate) {
  auto inst = bench::LoadBenchmarkInstance(kDir + "/corridor_N175.json");
  ASSERT_TRUE(inst.ok());
  auto session = Session::Create(inst->problem);
  ASSERT_TRUE(session.ok());
  ASSERT_TRUE((*session)->Solve(nullptr).ok());  // warms up lazily built state
  SolveLimits cold;
  cold.warm_start = false;
  const long before = g_allocations.load();
  auto s = (*session)->Solve(cold, nullptr);
  const long allocated = g_allocations.load() - before;
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(s->polished);
  EXPECT_LT(s->iterations, 20) << "not the interior-point iteration (IFFBDD's own takes 41 passes)";
  EXPECT_EQ(allocated, 0);
}

INSTANTIATE_TEST_SUITE_P(Algorithms, NoAllocationInLoop,
                         ::testing::Values(std::pair{"masses_N30", Algorithm::kIffbdd},
                                           std::pair{"corridor_N175", Algorithm::kIffbdd},
                                           std::pair{"ibffd_2d_N100", Algorithm::kIbffd},
                                           std::pair{"ibffd_2d_N100_hinge", Algorithm::kIbffd},
                                           std::pair{"ibffd_2d_N100_hinge", Algorithm::kIake},
                                           std::pair{"random_outbox_M40_K20_L20_N1000_s1", Algorithm::kIffbdd}),
                         [](const auto& info) {
                           return testing::ShortInstanceName(info.param.first) + "_" + AlgorithmName(info.param.second);
                         });

}  // namespace
}  // namespace nupmpc::core
