// EstimateFootprint (core/session/footprint.h) against what a Session really allocates:
// every malloc/free of the process is tracked by its usable size, and the peak of the
// live bytes over building the session's Problem copy, Session::Create and solves (cold,
// warm, after ReleaseWorkspace, with a Solution) must satisfy
//   measured ≤ estimate ≤ kSlack × measured
// over a grid of shapes (small and large M, L, K, N; time-varying and invariant; terminal
// cost, uncertain x[0]) and each algorithm. ReleaseWorkspace must give back at most the
// estimated workspace and at least a third of it.
#include "core/session/footprint.h"

#include <malloc.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>

#include "core/session/session.h"
#include "gtest/gtest.h"
#include "tests/util/random_problem.h"

// Under a sanitizer the allocator is the sanitizer's (with redzones): nothing to measure.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define NUPMPC_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define NUPMPC_SANITIZED 1
#endif
#endif

namespace {
std::atomic<long long> g_live{0};
std::atomic<long long> g_peak{0};

void Added(void* p) {
  if (p == nullptr) return;
  const long long now =
      g_live.fetch_add(static_cast<long long>(malloc_usable_size(p))) + static_cast<long long>(malloc_usable_size(p));
  long long peak = g_peak.load(std::memory_order_relaxed);
  while (now > peak && !g_peak.compare_exchange_weak(peak, now)) {
  }
}
void Removed(void* p) {
  if (p != nullptr) g_live.fetch_sub(static_cast<long long>(malloc_usable_size(p)));
}
}  // namespace

#ifndef NUPMPC_SANITIZED
extern "C" {
extern void* __libc_malloc(size_t);
extern void* __libc_calloc(size_t, size_t);
extern void* __libc_realloc(void*, size_t);
extern void* __libc_memalign(size_t, size_t);
extern void __libc_free(void*);
void* malloc(size_t n) {
  void* p = __libc_malloc(n);
  Added(p);
  return p;
}
void* calloc(size_t a, size_t b) {
  void* p = __libc_calloc(a, b);
  Added(p);
  return p;
}
void* realloc(void* old, size_t n) {
  Removed(old);
  void* p = __libc_realloc(old, n);
  Added(p);
  return p;
}
int posix_memalign(void** out, size_t alignment, size_t n) {
  *out = __libc_memalign(alignment, n);
  Added(*out);
  return *out == nullptr ? 12 /*ENOMEM*/ : 0;
}
void* aligned_alloc(size_t alignment, size_t n) {
  void* p = __libc_memalign(alignment, n);
  Added(p);
  return p;
}
void* memalign(size_t alignment, size_t n) {
  void* p = __libc_memalign(alignment, n);
  Added(p);
  return p;
}
void free(void* p) {
  Removed(p);
  __libc_free(p);
}
}
#endif

namespace nupmpc::core {
namespace {

constexpr double kSlack = 3.0;

struct Shape {
  int M, L, K, N;
  bool time_varying, terminal, free_x0;
};
enum class Kind { kIake, kIbffd, kIffbddAugmented, kIffbddOutputsOnly };

const char* KindName(Kind k) {
  switch (k) {
    case Kind::kIake:
      return "iake";
    case Kind::kIbffd:
      return "ibffd";
    case Kind::kIffbddAugmented:
      return "iffbdd_aug";
    case Kind::kIffbddOutputsOnly:
      return "iffbdd";
  }
  return "?";
}

#ifdef NUPMPC_SANITIZED
#define SKIP_UNDER_SANITIZER() GTEST_SKIP() << "the sanitizer's allocator: nothing to measure"
#else
#define SKIP_UNDER_SANITIZER() (void)0
#endif

TEST(TrackingMalloc, SeesTheTestsOwnAllocations) {
  SKIP_UNDER_SANITIZER();
  const long long before = g_live.load();
  auto* m = new Eigen::MatrixXd(100, 100);
  EXPECT_GE(g_live.load() - before, 100 * 100 * 8);
  delete m;
  EXPECT_LT(g_live.load() - before, 1024);
}

class Footprint : public ::testing::TestWithParam<std::tuple<Shape, Kind>> {};

TEST_P(Footprint, EstimateBoundsWhatASessionAllocates) {
  SKIP_UNDER_SANITIZER();
  const auto [shape, kind] = GetParam();
  testing::RandomProblemSpec spec;
  spec.M = shape.M;
  spec.L = shape.L;
  spec.K = shape.K;
  spec.N = shape.N;
  spec.time_varying = shape.time_varying;
  spec.offsets = shape.time_varying;
  spec.terminal = shape.terminal;
  spec.free_x0 = shape.free_x0;
  Problem p = testing::RandomGaussianProblem(spec);
  SolverOptions options;
  switch (kind) {
    case Kind::kIake:
      p = testing::WithBoxes(std::move(p), 0.5, 50.0);
      options.algorithm = Algorithm::kIake;
      break;
    case Kind::kIbffd:
      p = testing::WithBoxes(std::move(p), 0.5, 0.0);
      options.algorithm = Algorithm::kIbffd;
      break;
    case Kind::kIffbddAugmented:
      p = testing::WithBoxes(std::move(p), 0.5, 50.0);
      options.algorithm = Algorithm::kIffbdd;
      break;
    case Kind::kIffbddOutputsOnly:
      p = testing::WithBoxes(std::move(p), 0.0, 50.0);
      options.algorithm = Algorithm::kIffbdd;
      break;
  }
  const core::Footprint estimate = EstimateFootprint(ShapeOf(p, options.algorithm));

  SolveLimits limits;
  limits.max_iterations = shape.M >= 100 ? 2 : 6;
  const long long base = g_live.load();
  g_peak = base;
  long long held = 0, released = 0, problem = 0;
  {
    Problem copy = p;  // what the session will hold
    problem = g_live.load() - base;
    auto session = Session::Create(std::move(copy), options);
    ASSERT_TRUE(session.ok()) << session.status();
    Solution solution;
    ASSERT_TRUE((*session)->Solve(limits, &solution).ok());
    ASSERT_TRUE((*session)->Solve(limits, &solution).ok());  // warm: the polish with carried regions
    held = g_live.load() - base;
    (*session)->ReleaseWorkspace();
    released = held - (g_live.load() - base);
    ASSERT_TRUE((*session)->Solve(limits, &solution).ok());  // gets it back
  }
  const long long peak = g_peak.load() - base;
  std::printf(
      "%s M=%d L=%d K=%d N=%d: peak %.3f MB, estimate %.3f MB (%.2f x); problem %.3f/%.3f MB; "
      "released %.3f MB of %.3f MB estimated workspace\n",
      KindName(kind), shape.M, shape.L, shape.K, shape.N, peak / 1e6, estimate.total_bytes() / 1e6,
      static_cast<double>(estimate.total_bytes()) / peak, problem / 1e6, estimate.problem_bytes / 1e6, released / 1e6,
      estimate.workspace_bytes / 1e6);
  EXPECT_LE(peak, estimate.total_bytes());
  EXPECT_LE(static_cast<double>(estimate.total_bytes()), kSlack * peak);
  EXPECT_LE(problem, estimate.problem_bytes);
  EXPECT_LE(released, estimate.workspace_bytes);
  EXPECT_GE(3.0 * released, estimate.workspace_bytes);
}

INSTANTIATE_TEST_SUITE_P(
    Grid, Footprint,
    ::testing::Combine(::testing::Values(Shape{2, 1, 1, 20, false, false, false}, Shape{4, 2, 3, 50, true, true, true},
                                         Shape{12, 3, 12, 300, false, true, false},
                                         Shape{5, 40, 3, 100, false, false, false},
                                         Shape{40, 20, 20, 200, true, false, true},
                                         Shape{150, 15, 150, 30, false, true, false},
                                         Shape{300, 30, 300, 8, false, false, false}),
                       ::testing::Values(Kind::kIake, Kind::kIbffd, Kind::kIffbddAugmented, Kind::kIffbddOutputsOnly)),
    [](const auto& info) {
      const Shape s = std::get<0>(info.param);
      return std::string(KindName(std::get<1>(info.param))) + "_M" + std::to_string(s.M) + "L" + std::to_string(s.L) +
             "K" + std::to_string(s.K) + "N" + std::to_string(s.N) + (s.time_varying ? "tv" : "");
    });

}  // namespace
}  // namespace nupmpc::core
