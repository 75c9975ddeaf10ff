// Admission by cost: a request whose estimated memory or work is over the per-session
// limits, or over what is left of the server's memory budget, is refused with
// RESOURCE_EXHAUSTED naming the limit before anything is allocated; the server and its
// other sessions keep serving, and closing sessions gives the budget back.
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "server/convert/session_cost.h"
#include "server/observability/process_memory.h"
#include "tests/server/service/service_fixture.h"
#include "tests/util/random_problem.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kAddressSanitizer = true;
#else
constexpr bool kAddressSanitizer = false;
#endif
#else
constexpr bool kAddressSanitizer = false;
#endif

// x[n+1] = A x[n] + B u[n] with A = I (M×M), B = ones (M×1), K = 0: a valid spec whose
// size is all in M and N (one A, so the message stays small while the session would not).
v1::ProblemSpec IntegratorSpec(int M, int N) {
  v1::ProblemSpec spec;
  v1::Model* model = spec.mutable_model();
  model->set_num_states(M);
  model->set_num_inputs(1);
  model->set_num_outputs(0);
  model->set_horizon(N);
  v1::Matrix* a = model->add_a();
  a->set_rows(M);
  a->set_cols(M);
  a->mutable_data()->Resize(M * M, 0.0);
  for (int i = 0; i < M; ++i) a->set_data(i * M + i, 1.0);
  v1::Matrix* b = model->add_b();
  b->set_rows(M);
  b->set_cols(1);
  b->mutable_data()->Resize(M, 1.0);
  spec.mutable_initial_state()->mutable_mean()->Resize(M, 1.0);
  v1::ComponentPrior* u = spec.add_input_priors();
  u->set_kind(v1::PRIOR_KIND_BOX);
  u->add_weight(1.0);
  u->add_lower(-1.0);
  u->add_upper(1.0);
  v1::TerminalCost* terminal = spec.mutable_terminal();
  terminal->mutable_target()->Resize(M, 0.0);
  v1::Matrix* w = terminal->mutable_weight();
  w->set_rows(M);
  w->set_cols(M);
  w->mutable_data()->Resize(M * M, 0.0);
  for (int i = 0; i < M; ++i) w->set_data(i * M + i, 10.0);
  return spec;
}

class ServiceAdmissionTest : public ServiceTest {
 protected:
  void SetUp() override {
    ServiceTest::SetUp();
    instance_ = LoadInstanceOrDie("masses_N30");
    bystander_spec_ = SpecOrDie(instance_.problem);
  }
  // A session that is solved before and after each hostile request: its plan must not change.
  std::string OpenBystander() {
    auto created = client_->CreateSession(bystander_spec_);
    EXPECT_TRUE(created.ok()) << created.status();
    return created.ok() ? created->session_id() : "";
  }
  v1::Step BystanderStep() const {
    v1::Step step;
    const Eigen::VectorXd& x = instance_.closed_loop->x1[3];
    step.mutable_state()->Add(x.data(), x.data() + x.size());
    step.set_warm_start(v1::WARM_START_COLD);
    return step;
  }
  std::vector<double> BystanderPlan(const std::string& id) {
    auto r = client_->Solve(id, BystanderStep());
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok()) return {};
    EXPECT_TRUE(r->has_plan());
    return {r->inputs().begin(), r->inputs().end()};
  }
  bench::BenchmarkInstance instance_;
  v1::ProblemSpec bystander_spec_;
};

TEST_F(ServiceAdmissionTest, ASessionOverThePerSessionMemoryLimitIsRefusedBeforeAllocation) {
  const std::string bystander = OpenBystander();
  const std::vector<double> before = BystanderPlan(bystander);
  // The report's request: M = 1000, N = 3000 from one 1000×1000 A (an 8 MB message); the
  // solver would need M·M·(N+1) doubles per message.
  const v1::ProblemSpec huge = IntegratorSpec(1000, 3000);
  for (const absl::Status& s : {client_->CreateSession(huge).status(), client_->SolveOnce(huge).status()}) {
    EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
    EXPECT_THAT(std::string(s.message()), HasSubstr("max_session_bytes"));
    EXPECT_THAT(std::string(s.message()), HasSubstr("MiB"));
  }
  auto info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->active_sessions(), 1u);
  EXPECT_EQ(BystanderPlan(bystander), before);
}

TEST_F(ServiceAdmissionTest, EveryLevelCountHasALimitReportedInServerLimits) {
  auto info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok());
  const std::uint32_t limit = info->limits().max_input_levels();
  ASSERT_GE(limit, 2u);
  EXPECT_GT(info->limits().max_keep_out_regions(), 0u);
  EXPECT_GT(info->limits().max_session_bytes(), 0u);
  EXPECT_GT(info->limits().max_pass_flops(), 0.0);
  EXPECT_GT(info->limits().memory_budget_bytes(), 0u);
  const std::string bystander = OpenBystander();
  const std::vector<double> before = BystanderPlan(bystander);
  // 2^31 - 1 and 2^31 + 1 once overflowed an int; 100,000 made 99,999 binaries per step.
  for (std::uint32_t count : {2147483647u, 2147483649u, 100000u, limit + 1}) {
    SCOPED_TRACE(count);
    v1::ProblemSpec spec = IntegratorSpec(2, 20);
    v1::InputLevels* levels = spec.add_input_levels();
    levels->set_input(0);
    levels->set_count(count);
    levels->set_lowest(-1.0);
    levels->set_spacing(1.0);
    const absl::Status s = client_->CreateSession(spec).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
    EXPECT_THAT(std::string(s.message()), HasSubstr("spec.input_levels[0].count"));
  }
  EXPECT_EQ(BystanderPlan(bystander), before);
}

TEST_F(ServiceAdmissionTest, TheMemoryBudgetRefusesSessionsAndClosingGivesItBack) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  const v1::ProblemSpec spec = IntegratorSpec(60, 400);
  absl::StatusOr<server::SessionCost> cost = server::SpecCost(spec, options.size_limits);
  ASSERT_TRUE(cost.ok()) << cost.status();
  const std::int64_t per_session = cost->session_bytes();
  constexpr int kFits = 5;
  options.memory_budget_bytes = kFits * per_session + per_session / 2;
  StartServer(options);

  const std::uint64_t rss_before = server::ResidentMemoryBytes();
  std::vector<std::string> ids;
  absl::Status refused;
  for (int i = 0; i < 2 * kFits && refused.ok(); ++i) {
    auto created = client_->CreateSession(spec);
    if (!created.ok()) {
      refused = created.status();
      break;
    }
    ids.push_back(created->session_id());
    v1::Step step;  // solved once, so that its scratch is allocated too
    step.mutable_state()->Resize(60, 1.0);
    auto solved = client_->Solve(ids.back(), step);
    ASSERT_TRUE(solved.ok()) << solved.status();
    EXPECT_TRUE(solved->has_plan());
  }
  EXPECT_EQ(ids.size(), static_cast<std::size_t>(kFits));
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_THAT(std::string(refused.message()), HasSubstr("--memory_budget_mb"));
  auto info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->limits().memory_budget_bytes(), static_cast<std::uint64_t>(options.memory_budget_bytes));
  EXPECT_EQ(info->memory_reserved_bytes(), static_cast<std::uint64_t>(kFits * per_session));
  // The estimate bounds what the sessions really hold: the process grew by less than the
  // budget plus a fixed overhead (allocator slack, gRPC buffers). Not under ASan, whose
  // shadow memory and redzones are not ours to budget.
  const std::uint64_t rss_after = server::ResidentMemoryBytes();
  constexpr std::uint64_t kOverhead = 32u << 20;
  if (!kAddressSanitizer) {
    EXPECT_LT(rss_after, rss_before + static_cast<std::uint64_t>(options.memory_budget_bytes) + kOverhead)
        << "grew by " << (rss_after - rss_before) / 1024 << " KiB";
  }

  for (const std::string& id : ids) ASSERT_TRUE(client_->CloseSession(id).ok());
  info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->memory_reserved_bytes(), 0u);
  auto again = client_->CreateSession(spec);
  EXPECT_TRUE(again.ok()) << again.status();
}

TEST_F(ServiceAdmissionTest, AnIdleSessionGivesItsScratchBackAndTakesItAgainOnItsNextSolve) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.session_compact_idle_s = 0.05;  // the janitor compacts sessions idle this long
  StartServer(options);
  const v1::ProblemSpec spec = IntegratorSpec(40, 200);
  absl::StatusOr<server::SessionCost> cost = server::SpecCost(spec, options.size_limits);
  ASSERT_TRUE(cost.ok());
  auto created = client_->CreateSession(spec);
  ASSERT_TRUE(created.ok()) << created.status();
  v1::Step step;
  step.mutable_state()->Resize(40, 1.0);
  ASSERT_TRUE(client_->Solve(created->session_id(), step).ok());
  std::uint64_t reserved = 0;
  for (int i = 0; i < 200; ++i) {  // up to 10 s for the janitor on a loaded machine
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    reserved = client_->GetServerInfo()->memory_reserved_bytes();
    if (reserved == static_cast<std::uint64_t>(cost->session_bytes() - cost->scratch_bytes)) break;
  }
  EXPECT_EQ(reserved, static_cast<std::uint64_t>(cost->session_bytes() - cost->scratch_bytes));
  auto solved = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(solved.ok()) << solved.status();
  EXPECT_TRUE(solved->has_plan());
}

TEST_F(ServiceAdmissionTest, ASessionBuiltAfterItsCallsDeadlineIsNotRegistered) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.worker_threads = 1;
  StartServer(options);
  // Big enough that building it takes longer than a 1 ms deadline anywhere.
  const v1::ProblemSpec spec = IntegratorSpec(100, 1000);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(1));
  v1::CreateSessionRequest request;
  *request.mutable_spec() = spec;
  v1::CreateSessionResponse response;
  const grpc::Status status = client_->stub().CreateSession(&context, request, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  // The one worker is free once it serves the next call; by then the build has ended.
  ASSERT_TRUE(client_->SolveOnce(bystander_spec_).ok());
  auto sessions = client_->ListSessions();
  ASSERT_TRUE(sessions.ok());
  EXPECT_TRUE(sessions->empty()) << sessions->size() << " sessions registered";
}

// A dense plant (the report's M = 300, L = 30, K = 300 shape, scaled to the test machine)
// whose solve takes many times the call's deadline: the worker is free soon after the
// deadline, not after the solve. Measured against the same solve without a deadline, so
// the bound scales with the machine; it leaves half the solve for the session's build
// before the solve, the hand-offs and a loaded machine (under the suite's load, the next
// call was seen 0.20 s in with a 0.086 s deadline of a 0.86 s solve: within a quarter of
// the earlier bound, deadline + a fifth of the solve).
// That a limit stops a pass in its middle is the core's test (interrupt_test, LargeSolve).
TEST_F(ServiceAdmissionTest, ASolveFarLongerThanItsDeadlineFreesItsWorkerSoonAfterIt) {
  server_->Shutdown();
  server::ServerOptions options = DefaultOptions();
  options.worker_threads = 1;
  StartServer(options);
  RandomProblemSpec shape;
  shape.M = 120;
  shape.L = 12;
  shape.K = 120;
  shape.N = 100;
  shape.time_varying = false;  // one A: a small message for a large session
  shape.seed = 11;
  const v1::ProblemSpec dense = SpecOrDie(WithBoxes(RandomGaussianProblem(shape), 0.5, 0.2));
  ASSERT_TRUE(client_->SolveOnce(bystander_spec_).ok());  // warm: connection and code paths

  auto start = std::chrono::steady_clock::now();
  absl::StatusOr<v1::SolveResult> full = client_->SolveOnce(dense);
  const double full_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(full.ok()) << full.status();
  const double deadline_s = full_s / 10.0;
  Client impatient(target_, std::chrono::milliseconds(static_cast<int>(deadline_s * 1000.0) + 1));
  start = std::chrono::steady_clock::now();
  const absl::StatusOr<v1::SolveResult> abandoned = impatient.SolveOnce(dense);
  // The client's deadline ends the call; the server stops the solve at the same deadline,
  // and on a loaded machine its answer (cut short, a time limit) may arrive first.
  if (abandoned.ok()) {
    EXPECT_EQ(abandoned->status(), v1::SOLVE_STATUS_TIME_LIMIT);
  } else {
    EXPECT_EQ(abandoned.status().code(), absl::StatusCode::kDeadlineExceeded) << abandoned.status();
  }
  absl::StatusOr<v1::SolveResult> next = client_->SolveOnce(bystander_spec_);  // waits for the only worker
  const double free_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(next.ok()) << next.status();
  std::printf("full solve %.3f s (%u passes); with a %.3f s deadline the worker answered the next call %.3f s in\n",
              full_s, full->iterations(), deadline_s, free_s);
  EXPECT_LT(free_s, deadline_s + full_s / 2.0) << "the worker stayed with the abandoned solve";
}

}  // namespace
}  // namespace nupmpc::testing
