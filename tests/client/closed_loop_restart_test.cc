// `nupmpc closed-loop` rides through a server restart: the real CLI binary drives a
// simulated masses_N30 plant through the real nupmpc-server binary, which is killed with
// SIGKILL mid-run and started again on the same port 1 s (and 5 s) later (and once with
// SIGTERM and a state directory, which hands the session over warm). The run must
// finish every step with exit 0 and its summary must report the reconnect and how long
// the plant went without a fresh plan, and that the session, asked for by its id first,
// was re-created (after SIGKILL the restarted server does not have it). And a step whose result carries
// no plan (SolveResult.has_plan false) is never applied: the CLI holds the last input.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/problem_file.h"
#include "google/protobuf/util/json_util.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/util/server_process.h"

namespace nupmpc::testing {
namespace {

std::string Target(int port) { return "127.0.0.1:" + std::to_string(port); }

// nupmpc-server with one worker on 127.0.0.1:port and `extra` flags; killed (SIGKILL)
// when destroyed.
std::unique_ptr<ServerProcess> StartServer(int port, const std::vector<std::string>& extra = {}) {
  std::vector<std::string> flags = {"--log_level=warn", "--threads=1"};
  flags.insert(flags.end(), extra.begin(), extra.end());
  return std::make_unique<ServerProcess>(NUPMPC_SERVER_BINARY, port, flags);
}

// How the server goes away mid-run: SIGKILL (a crash), or SIGTERM (a drain, which with a
// --state_dir among `flags` writes the sessions' snapshots); `flags` go to both processes.
struct Restart {
  int signal = SIGKILL;
  std::vector<std::string> flags;
};

// masses_N30 as a ProblemSpec file: no recorded states, so the CLI simulates the plant
// with the inputs it applies. `initial_state` replaces x[0] when given.
// ctest runs each test of this file as its own process, in parallel: every scratch file
// carries the process id so that one test never truncates a file another is writing.
std::filesystem::path ScratchPath(const std::string& name) {
  return std::filesystem::path(::testing::TempDir()) / absl::StrCat(name, ".", getpid());
}

std::string WriteSpec(const std::string& name, const std::vector<double>& initial_state = {}) {
  absl::StatusOr<ProblemFile> problem = LoadProblemFile(std::string(NUPMPC_BENCHMARK_DIR) + "/masses_N30.json");
  EXPECT_TRUE(problem.ok()) << problem.status();
  if (!problem.ok()) return "";
  if (!initial_state.empty()) {
    problem->spec.mutable_initial_state()->mutable_mean()->Assign(initial_state.begin(), initial_state.end());
  }
  std::string text;
  EXPECT_TRUE(google::protobuf::util::MessageToJsonString(problem->spec, &text).ok());
  const std::filesystem::path path = ScratchPath(name);
  std::ofstream(path) << text;
  return path.string();
}

struct CliRun {
  int exit_code = -1;
  std::vector<nlohmann::json> steps;  // one object per step line
  nlohmann::json summary;
  std::string stderr_text;
  std::chrono::duration<double> took{};
};

// Runs `nupmpc --format=json closed-loop spec`; `on_step(step)` is called for each step
// line as it is read. The CLI's stdout is a pipe of one page, so the CLI cannot run more
// than a few steps ahead of this reader.
template <typename OnStep>
CliRun RunCli(int port, const std::string& spec, std::vector<std::string> flags, OnStep on_step) {
  CliRun run;
  const std::filesystem::path err_path = ScratchPath("closed_loop_stderr");
  int out[2];
  if (pipe(out) != 0) return run;
  (void)fcntl(out[1], F_SETPIPE_SZ, 4096);
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid == 0) {
    alarm(120);  // never hang the test run
    const int err = open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(out[1], STDOUT_FILENO);
    dup2(err, STDERR_FILENO);
    close(out[0]);
    std::vector<std::string> args = {NUPMPC_CLI_BINARY, "--server=" + Target(port), "--format=json"};
    args.insert(args.end(), flags.begin(), flags.end());
    args.push_back("closed-loop");
    args.push_back(spec);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(NUPMPC_CLI_BINARY, argv.data());
    _exit(127);
  }
  close(out[1]);
  FILE* in = fdopen(out[0], "r");
  char* line = nullptr;
  size_t capacity = 0;
  while (getline(&line, &capacity, in) > 0) {
    nlohmann::json object = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (object.is_discarded()) continue;
    if (object.contains("summary")) {
      run.summary = object;
    } else {
      run.steps.push_back(object);
      on_step(object["step"].get<int>());
    }
  }
  free(line);
  fclose(in);
  int status = 0;
  waitpid(pid, &status, 0);
  run.took = std::chrono::steady_clock::now() - start;
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  std::ifstream err(err_path);
  std::stringstream text;
  text << err.rdbuf();
  run.stderr_text = text.str();
  return run;
}

// Kills the server when the CLI has printed step `kill_at`, waits `down_for`, starts it
// again on the same port, and lets the run finish. On a thread of its own, so that this
// reader keeps draining the pipe meanwhile: a CLI blocked writing to a full pipe would see
// the break only after the restart, and reconnect at its first attempt.
CliRun RunThroughRestart(std::chrono::milliseconds down_for, int steps, int kill_at, const Restart& how = {}) {
  const int port = FreeLoopbackPort();
  auto server = StartServer(port, how.flags);
  EXPECT_TRUE(WaitUntilServing(Target(port)));
  const std::string spec = WriteSpec("masses_N30_spec.json");
  std::thread restarter;
  CliRun run = RunCli(port, spec, {"--steps=" + std::to_string(steps), "--reconnect_budget_s=25"}, [&](int step) {
    if (restarter.joinable() || step < kill_at) return;
    restarter = std::thread([&] {
      if (how.signal == SIGKILL) {
        server->Kill();
      } else {
        EXPECT_EQ(server->StopWith(how.signal), 0) << "the server did not drain and exit cleanly";
      }
      std::this_thread::sleep_for(down_for);
      server = StartServer(port, how.flags);
    });
  });
  EXPECT_TRUE(restarter.joinable()) << "the run ended before step " << kill_at;
  if (restarter.joinable()) restarter.join();
  return run;
}

void ExpectRodeThrough(const CliRun& run, int steps, double down_s) {
  EXPECT_EQ(run.exit_code, 0) << run.stderr_text;
  ASSERT_EQ(static_cast<int>(run.steps.size()), steps) << run.stderr_text;
  ASSERT_TRUE(run.summary.is_object()) << run.stderr_text;
  EXPECT_EQ(run.summary["steps"], steps);
  EXPECT_EQ(run.summary["reconnects"], 1) << run.summary.dump();
  EXPECT_GE(run.summary["reconnect_attempts"].get<int>(), 2) << run.summary.dump();
  // Every step after the restart got a plan (the interrupted one was resent): none held.
  EXPECT_EQ(run.summary["held_steps"], 0) << run.summary.dump();
  for (const nlohmann::json& step : run.steps) EXPECT_TRUE(step["has_plan"].get<bool>()) << step.dump();
  // The plant went without a fresh plan for at least the outage, and not for much longer
  // than the back-off's reach (2 s ± 20 %; generous: a slow shared machine).
  const double without_plan = run.summary["longest_without_plan_s"].get<double>();
  EXPECT_GE(without_plan, down_s) << run.summary.dump();
  EXPECT_LT(without_plan, down_s + 6.0) << run.summary.dump();
  EXPECT_GE(run.summary["reconnect_s"].get<double>(), 0.9 * down_s) << run.summary.dump();
  // Each attempt was logged, and the reconnect.
  EXPECT_NE(run.stderr_text.find("the Control stream broke"), std::string::npos) << run.stderr_text;
  EXPECT_NE(run.stderr_text.find("reconnect attempt 1 "), std::string::npos) << run.stderr_text;
  EXPECT_NE(run.stderr_text.find("reconnected at attempt"), std::string::npos) << run.stderr_text;
  // The session was asked for by its id first; a server restarted without a state
  // directory does not have it (NOT_FOUND), so it was re-created from the spec: cold.
  EXPECT_EQ(run.summary["reattached"], 0) << run.summary.dump();
  EXPECT_EQ(run.summary["recreated"], 1) << run.summary.dump();
  EXPECT_NE(run.stderr_text.find("session re-created (attach by id: NOT_FOUND"), std::string::npos) << run.stderr_text;
}

TEST(ClosedLoopRestart, ServerKilledAndBackAfter1s) {
  const CliRun run = RunThroughRestart(std::chrono::milliseconds(1000), /*steps=*/400, /*kill_at=*/100);
  ExpectRodeThrough(run, 400, 1.0);
  std::printf("1 s outage: %s (%.2f s in all)\n", run.summary.dump().c_str(), run.took.count());
}

TEST(ClosedLoopRestart, ServerKilledAndBackAfter5s) {
  const CliRun run = RunThroughRestart(std::chrono::milliseconds(5000), /*steps=*/400, /*kill_at=*/100);
  ExpectRodeThrough(run, 400, 5.0);
  std::printf("5 s outage: %s (%.2f s in all)\n", run.summary.dump().c_str(), run.took.count());
}

// SIGTERM with a state directory (bumpless hand-over): the draining server writes the
// session's snapshot and the restarted one restores it when the CLI's reconnect attaches by
// its id, so the session comes back re-attached (warm), not re-created, and every step is
// done.
TEST(ClosedLoopRestart, SigtermWithAStateDirectoryReattachesTheSession) {
  const std::filesystem::path state_dir = ScratchPath("state_dir");
  std::filesystem::remove_all(state_dir);
  const CliRun run =
      RunThroughRestart(std::chrono::milliseconds(500), /*steps=*/400, /*kill_at=*/100,
                        Restart{SIGTERM, {absl::StrCat("--state_dir=", state_dir.string()), "--grace_period_s=2"}});
  std::filesystem::remove_all(state_dir);
  EXPECT_EQ(run.exit_code, 0) << run.stderr_text;
  ASSERT_EQ(static_cast<int>(run.steps.size()), 400) << run.stderr_text;
  EXPECT_EQ(run.summary["reconnects"], 1) << run.summary.dump();
  EXPECT_EQ(run.summary["reattached"], 1) << run.summary.dump() << "\n" << run.stderr_text;
  EXPECT_EQ(run.summary["recreated"], 0) << run.summary.dump();
  EXPECT_EQ(run.summary["held_steps"], 0) << run.summary.dump();
  EXPECT_NE(run.stderr_text.find("session re-attached by its id"), std::string::npos) << run.stderr_text;
}

// The budget bounds the wait: with the server gone for good, the CLI gives up after about
// --reconnect_budget_s and exits 1 naming the attempts.
TEST(ClosedLoopRestart, GivesUpWhenTheBudgetIsSpent) {
  const int port = FreeLoopbackPort();
  auto server = StartServer(port);
  ASSERT_TRUE(WaitUntilServing(Target(port)));
  const std::string spec = WriteSpec("masses_N30_spec.json");
  const CliRun run = RunCli(port, spec, {"--steps=400", "--reconnect_budget_s=1"}, [&](int step) {
    if (step == 20) server->Kill();
  });
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_LT(static_cast<int>(run.steps.size()), 400);
  EXPECT_NE(run.stderr_text.find("gave up reconnecting after"), std::string::npos) << run.stderr_text;
  EXPECT_NE(run.stderr_text.find("giving up"), std::string::npos) << run.stderr_text;
  EXPECT_LT(run.took.count(), 20.0);
}

// A step with x0 = [-1e300, 0, ...] after a normal one comes back
// NUMERICAL_ERROR without a plan (the server used to return the previous step's plan with
// it). The CLI, replaying recorded states, must hold the input it applied before and say
// so; the next normal step applies its own plan again.
TEST(ClosedLoopNoPlan, AStepWithoutAPlanHoldsTheLastInput) {
  std::ifstream in(std::string(NUPMPC_BENCHMARK_DIR) + "/masses_N30.json");
  nlohmann::json instance = nlohmann::json::parse(in);
  nlohmann::json& recorded = instance["closed_loop"];
  std::vector<double> bad(recorded["x1"][0].size(), 0.0);
  bad[0] = -1e300;
  recorded["x1"] = nlohmann::json::array({recorded["x1"][0], bad, recorded["x1"][2]});
  recorded["w"] = nlohmann::json::array({recorded["w"][0], recorded["w"][1], recorded["w"][2]});
  recorded["u_applied"] =
      nlohmann::json::array({recorded["u_applied"][0], recorded["u_applied"][1], recorded["u_applied"][2]});
  recorded["T"] = 3;
  const std::filesystem::path path = ScratchPath("masses_N30_bad_state.json");
  std::ofstream(path) << instance.dump();

  const int port = FreeLoopbackPort();
  const std::unique_ptr<ServerProcess> server = StartServer(port);
  ASSERT_TRUE(WaitUntilServing(Target(port)));
  const CliRun run = RunCli(port, path.string(), {}, [](int) {});
  EXPECT_EQ(run.exit_code, 0) << run.stderr_text;
  ASSERT_EQ(run.steps.size(), 3u) << run.stderr_text;
  EXPECT_TRUE(run.steps[0]["has_plan"].get<bool>()) << run.steps[0].dump();
  EXPECT_EQ(run.steps[1]["status"], "numerical_error") << run.steps[1].dump();
  EXPECT_FALSE(run.steps[1]["has_plan"].get<bool>()) << run.steps[1].dump();
  EXPECT_EQ(run.steps[1]["u0"], run.steps[0]["u0"]);  // held, not the result's inputs
  EXPECT_TRUE(run.steps[2]["has_plan"].get<bool>()) << run.steps[2].dump();
  EXPECT_EQ(run.summary["held_steps"], 1) << run.summary.dump();
  EXPECT_EQ(run.summary["held"]["numerical_error"], 1) << run.summary.dump();
  EXPECT_EQ(run.summary["not_converged"]["numerical_error"], 1) << run.summary.dump();
}

}  // namespace
}  // namespace nupmpc::testing
