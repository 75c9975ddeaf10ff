// nupmpc: command-line client of nupmpc-server.
//
//   nupmpc solve FILE          one stateless solve (SolveOnce)
//   nupmpc closed-loop FILE    a receding-horizon run through a Control stream: the
//                              instance's recorded closed-loop states if it has them,
//                              else the model simulated locally (optional --noise)
//   nupmpc fit-gp FILE         GP hyper-parameters by maximum likelihood (FitGpModel);
//                              FILE is a FitGpModelRequest in proto JSON
//   nupmpc info                server version, limits, counters
//   nupmpc sessions            open sessions
//
// FILE is an instance in the benchmarks/ format or a ProblemSpec in proto JSON.
// --format table|json; with json, closed-loop prints one object per step and line with
// step, t_s (seconds since the loop started, when the step returned), state (the x sent),
// objective, iterations, solve_ms, round_trip_ms, status, max_violation, has_plan, held
// (no plan this period: the input was held), u0 (the input applied: the plan's u[0], or
// the held one), then one summary object ("summary": true); with table, a summary after
// the steps, in words.
//
// --period_ms P: a closed loop in real time. A step starts every P ms and returns by its
// period: without an answer by then it is held (status "held"), and a late answer is
// discarded; after K held periods in a row (K = max(3, 1 s / P)) the stream counts as
// broken and is reconnected in the background, for as long as the loop runs (back-off at
// most 500 ms, attempts of at most 1 s; client/session.h). Without a period, steps run as
// fast as answers come, and a broken stream is reconnected with exponential back-off (50 ms
// doubling to --reconnect_max_backoff_ms, ±20 % jitter) for at most --reconnect_budget_s
// per outage. Either way each reconnect attempt is logged on stderr, and the session is
// re-attached by its id when the server still has it (or restored it), else re-created
// from the spec (client/reconnect.h); the summary counts both ("reattached", "recreated").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <thread>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "cli/program_flags.h"
#include "client/client.h"
#include "client/closed_loop_summary.h"
#include "client/problem_file.h"
#include "client/security_flags.h"
#include "client/server_info_table.h"
#include "client/solve_status_name.h"
#include "google/protobuf/util/json_util.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "server address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(std::string, format, "table", "table or json");
ABSL_FLAG(int, steps, 0, "closed-loop: number of steps (0: the instance's sequence, or 50)");
ABSL_FLAG(double, noise, 0.0, "closed-loop simulation: std. dev. of additive state noise");
ABSL_FLAG(int, seed, 1, "closed-loop simulation: noise seed");
ABSL_FLAG(int, deadline_ms, 0, "deadline of unary calls (0: none)");
ABSL_FLAG(double, reconnect_budget_s, 30.0,
          "closed-loop: how long to keep trying to re-attach after the stream broke (per outage; 0: not at all)");
ABSL_FLAG(int, reconnect_max_backoff_ms, 2000, "closed-loop: the longest wait between two reconnect attempts");
ABSL_FLAG(int, period_ms, 0,
          "closed-loop: the control period: a step every period, held when its answer has not come by the end of "
          "it (0: no period, steps as fast as answers come)");

namespace {

namespace v1 = nupmpc::v1;
using nupmpc::SolveStatusName;

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc",
    .summary =
        "nupmpc: command-line client of nupmpc-server.\n"
        "  solve FILE        one stateless solve (SolveOnce)\n"
        "  closed-loop FILE  a receding-horizon run through a Control stream: the instance's recorded\n"
        "                    closed-loop states if it has them, else the model simulated locally\n"
        "                    (--noise); ends with a summary (convergence, steps without a plan,\n"
        "                    reconnects, solve and round-trip times); rides through a server restart\n"
        "                    (--reconnect_budget_s)\n"
        "  fit-gp FILE       GP hyper-parameters by maximum likelihood (FitGpModel); FILE is a\n"
        "                    FitGpModelRequest in proto JSON\n"
        "  info              server version, CPU baseline, limits, counters\n"
        "  sessions          open sessions\n"
        "FILE is an instance in the benchmarks/ format or a ProblemSpec in proto JSON.",
    .usage =
        "nupmpc [--server HOST:PORT] [--format table|json] solve FILE | closed-loop FILE | fit-gp FILE | info | "
        "sessions",
    .environment = {{"NUPMPC_SERVER", "server address when --server is not given"},
                    {"NUPMPC_TOKEN", "the bearer token, when --token_file and NUPMPC_TOKEN_FILE are not given"},
                    {"NUPMPC_TLS, NUPMPC_TLS_CA_FILE, ...", "each --tls* flag's value when the flag is not given"}},
    .max_arguments = 2,
};

std::string U0(const v1::SolveResult& r, int L) {
  std::vector<std::string> parts;
  for (int l = 0; l < L && l < r.inputs_size(); ++l) parts.push_back(absl::StrCat(r.inputs(l)));
  return absl::StrCat("[", absl::StrJoin(parts, ","), "]");
}

std::string Vector(const std::vector<double>& v) {
  std::vector<std::string> parts;
  parts.reserve(v.size());
  for (const double value : v) parts.push_back(absl::StrCat(value));
  return absl::StrCat("[", absl::StrJoin(parts, ","), "]");
}

// A number in JSON: null where it is not finite (a result without a plan has NaN objective).
std::string JsonNumber(double value) {
  return std::isfinite(value) ? absl::StrFormat("%.17g", value) : std::string("null");
}

// A vector in JSON, every number exact (a reader may re-solve for a printed state).
std::string JsonVector(const std::vector<double>& v) {
  std::vector<std::string> parts;
  parts.reserve(v.size());
  for (const double value : v) parts.push_back(JsonNumber(value));
  return absl::StrCat("[", absl::StrJoin(parts, ","), "]");
}

void PrintResult(const v1::SolveResult& r, int L, bool json) {
  // A result without a plan has no inputs to show (SolveResult.has_plan).
  const std::string u0 = nupmpc::HasPlan(r) ? U0(r, L) : (json ? "null" : "none (no plan)");
  if (json) {
    std::printf(
        "{\"status\":\"%s\",\"objective\":%s,\"iterations\":%u,\"solve_ms\":%.6f,\"max_violation\":%s,"
        "\"has_plan\":%s,\"u0\":%s}\n",
        SolveStatusName(r.status()).c_str(), JsonNumber(r.objective()).c_str(), r.iterations(), r.solve_ms(),
        JsonNumber(r.max_violation()).c_str(), nupmpc::HasPlan(r) ? "true" : "false", u0.c_str());
  } else {
    std::printf("status %s, %u iterations, %.4f ms, J = %.12g, max violation %.3g\nu[0] = %s\n",
                SolveStatusName(r.status()).c_str(), r.iterations(), r.solve_ms(), r.objective(), r.max_violation(),
                u0.c_str());
  }
}

// A response as proto JSON: one line with --format json, indented otherwise.
void PrintJson(const google::protobuf::Message& message, bool one_line) {
  std::string text;
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = !one_line;
  (void)google::protobuf::util::MessageToJsonString(message, &text, options);
  std::printf("%s\n", text.c_str());
}

int Fail(const absl::Status& s) {
  std::fprintf(stderr, "nupmpc: %s\n", s.ToString().c_str());
  return 1;
}

// x ← A x + B u (+ c) (+ noise), from the spec's first (time-invariant) matrices.
std::vector<double> Simulate(const v1::ProblemSpec& spec, const std::vector<double>& x, const std::vector<double>& u,
                             std::normal_distribution<double>& noise, std::mt19937_64& rng) {
  const v1::Model& m = spec.model();
  const int M = static_cast<int>(m.num_states()), L = static_cast<int>(m.num_inputs());
  std::vector<double> next(M, 0.0);
  for (int i = 0; i < M; ++i) {
    for (int j = 0; j < M; ++j) next[i] += m.a(0).data(i * M + j) * x[j];
    for (int l = 0; l < L; ++l) next[i] += m.b(0).data(i * L + l) * u[l];
    if (m.state_offset_size() >= M) next[i] += m.state_offset(i);
    if (noise.stddev() > 0) next[i] += noise(rng);
  }
  return next;
}

int ClosedLoop(nupmpc::Client& client, const nupmpc::ProblemFile& problem, bool json) {
  if (problem.spec.has_gp()) {
    // Simulating needs the plant; a GP spec only has data about it.
    return Fail(absl::InvalidArgumentError(
        "closed-loop: a GP spec has no plant model to simulate; drive a GP session from your own loop (Control "
        "stream or Solve, the past window as Step.state)"));
  }
  nupmpc::ReconnectOptions reconnect;
  reconnect.budget =
      std::chrono::milliseconds(std::llround(1e3 * std::max(0.0, absl::GetFlag(FLAGS_reconnect_budget_s))));
  reconnect.max_backoff = std::chrono::milliseconds(std::max(1, absl::GetFlag(FLAGS_reconnect_max_backoff_ms)));
  reconnect.on_attempt = [](const nupmpc::ReconnectAttempt& a) {
    if (a.attempt == 0) {  // a zero budget: no attempt at all
      std::fprintf(stderr, "nupmpc: the Control stream broke (%s); not reconnecting (--reconnect_budget_s 0)\n",
                   a.cause.ToString().c_str());
      return;
    }
    if (a.attempt == 1) {
      std::fprintf(stderr, "nupmpc: the Control stream broke (%s); reconnecting\n", a.cause.ToString().c_str());
    }
    if (a.result.ok()) {
      const std::string how = a.path == nupmpc::ReconnectPath::kReattached
                                  ? "session re-attached by its id"
                                  : absl::StrCat("session re-created",
                                                 a.attach_by_id.has_value()
                                                     ? absl::StrCat(" (attach by id: ", a.attach_by_id->ToString(), ")")
                                                     : std::string());
      std::fprintf(stderr, "nupmpc: reconnected at attempt %d, %.3f s after the break; %s\n", a.attempt,
                   1e-3 * static_cast<double>(a.elapsed.count()), how.c_str());
    } else {
      std::fprintf(stderr, "nupmpc: reconnect attempt %d (after %lld ms back-off, %.3f s after the break): %s%s\n",
                   a.attempt, static_cast<long long>(a.waited.count()), 1e-3 * static_cast<double>(a.elapsed.count()),
                   a.result.ToString().c_str(), a.gave_up ? "; giving up" : "");
    }
  };
  const std::chrono::milliseconds period(std::max(0, absl::GetFlag(FLAGS_period_ms)));
  absl::StatusOr<std::unique_ptr<nupmpc::Session>> session =
      client.OpenSession(problem.spec, reconnect, nupmpc::ControlPeriod{.period = period});
  if (!session.ok()) return Fail(session.status());
  const int L = static_cast<int>(problem.spec.model().num_inputs());
  const bool recorded = !problem.closed_loop_states.empty();
  int steps = absl::GetFlag(FLAGS_steps);
  if (steps <= 0) steps = recorded ? static_cast<int>(problem.closed_loop_states.size()) : 50;
  if (recorded) steps = std::min<int>(steps, problem.closed_loop_states.size());
  std::mt19937_64 rng(absl::GetFlag(FLAGS_seed));
  std::normal_distribution<double> noise(0.0, absl::GetFlag(FLAGS_noise));
  std::vector<double> x(problem.spec.initial_state().mean().begin(), problem.spec.initial_state().mean().end());
  if (!json)
    std::printf("%5s %-16s %6s %10s %10s %18s %10s  %s\n", "step", "status", "iter", "solve_ms", "rtt_ms", "objective",
                "max_viol", "u0");
  std::vector<nupmpc::ClosedLoopStep> record;
  // The input applied to the plant: the plan's u[0] when the result has one, else the
  // last one applied (zero before the first plan).
  std::vector<double> u(L, 0.0);
  using Clock = std::chrono::steady_clock;
  const Clock::time_point loop_start = Clock::now();
  Clock::time_point last_plan = loop_start, next_step = loop_start;
  double longest_without_plan_s = 0.0;
  for (int t = 0; t < steps; ++t) {
    // In real time: one step per period, never a burst to catch up after a late one.
    std::this_thread::sleep_until(next_step);
    next_step = std::max(next_step + period, Clock::now());
    if (recorded) x = problem.closed_loop_states[t];
    const std::string state = JsonVector(x);
    v1::Step step;
    step.mutable_state()->Add(x.begin(), x.end());
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<v1::SolveResult> r = (*session)->Step(step);
    const double rtt_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!r.ok()) return Fail(r.status());
    const bool has_plan = nupmpc::HasPlan(*r) && r->inputs_size() >= L;
    if (has_plan) {
      u.assign(r->inputs().begin(), r->inputs().begin() + L);
      longest_without_plan_s =
          std::max(longest_without_plan_s, std::chrono::duration<double>(Clock::now() - last_plan).count());
      last_plan = Clock::now();
    }
    record.push_back({r->status(), r->solve_ms(), rtt_ms, r->max_violation(), has_plan});
    if (json) {
      std::printf(
          "{\"step\":%d,\"t_s\":%.6f,\"state\":%s,\"status\":\"%s\",\"objective\":%s,\"iterations\":%u,"
          "\"solve_ms\":%.6f,\"round_trip_ms\":%.6f,\"max_violation\":%s,\"warm_started\":%s,\"has_plan\":%s,"
          "\"held\":%s,\"u0\":%s}\n",
          t, std::chrono::duration<double>(Clock::now() - loop_start).count(), state.c_str(),
          SolveStatusName(r->status()).c_str(), JsonNumber(r->objective()).c_str(), r->iterations(), r->solve_ms(),
          rtt_ms, JsonNumber(r->max_violation()).c_str(), r->warm_started() ? "true" : "false",
          has_plan ? "true" : "false", has_plan ? "false" : "true", JsonVector(u).c_str());
    } else {
      std::printf("%5d %-16s %6u %10.4f %10.4f %18.10g %10.3g  %s%s\n", t, SolveStatusName(r->status()).c_str(),
                  r->iterations(), r->solve_ms(), rtt_ms, r->objective(), r->max_violation(), Vector(u).c_str(),
                  has_plan ? "" : " (no plan: held)");
    }
    std::fflush(stdout);
    if (!recorded) x = Simulate(problem.spec, x, u, noise, rng);
  }
  longest_without_plan_s =
      std::max(longest_without_plan_s, std::chrono::duration<double>(Clock::now() - last_plan).count());
  // Every step has been reported: a goodbye that failed (a stream that broke after the last
  // step) is worth a warning, not the run's summary.
  if (absl::Status s = (*session)->Close(); !s.ok()) {
    std::fprintf(stderr, "nupmpc: closing the session: %s\n", s.ToString().c_str());
  }
  nupmpc::ClosedLoopSummary summary = nupmpc::SummariseClosedLoop(record);
  const nupmpc::ReconnectStats reconnects = (*session)->reconnect_stats();
  summary.reconnects = reconnects.reconnects;
  summary.reattached = reconnects.reattached;
  summary.recreated = reconnects.recreated;
  summary.reconnect_attempts = reconnects.attempts;
  summary.reconnect_s = 1e-3 * static_cast<double>(reconnects.total.count());
  summary.longest_without_plan_s = longest_without_plan_s;
  summary.late_answers = (*session)->late_answers();
  summary.period_ms = static_cast<double>(period.count());
  // Not `"\n" + text`: GCC 12 warns about it (-Wrestrict, a false positive fixed in GCC 13).
  if (json) {
    std::fputs(nupmpc::SummaryJson(summary).c_str(), stdout);
  } else {
    std::printf("\n%s", nupmpc::SummaryText(summary).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (const char* env = std::getenv("NUPMPC_SERVER"); env != nullptr) absl::SetFlag(&FLAGS_server, env);
  std::vector<char*> args = nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  if (args.size() < 2) return nupmpc::cli::ReportUsageError(kProgram, "no command given");
  const std::string command = args[1];
  const std::string format = absl::GetFlag(FLAGS_format);
  if (format != "table" && format != "json") {
    return nupmpc::cli::ReportUsageError(kProgram, absl::StrCat("--format ", format, ": must be table or json"));
  }
  const bool json = format == "json";
  absl::StatusOr<nupmpc::ChannelSecurity> security = nupmpc::ChannelSecurityFromFlags();
  if (!security.ok()) return Fail(security.status());
  absl::StatusOr<std::unique_ptr<nupmpc::Client>> connected = nupmpc::Client::Connect(
      absl::GetFlag(FLAGS_server), *security, std::chrono::milliseconds(absl::GetFlag(FLAGS_deadline_ms)));
  if (!connected.ok()) return Fail(connected.status());
  nupmpc::Client& client = **connected;

  if (command == "solve" || command == "closed-loop") {
    if (args.size() < 3) return nupmpc::cli::ReportUsageError(kProgram, absl::StrCat(command, ": FILE missing"));
    absl::StatusOr<nupmpc::ProblemFile> problem = nupmpc::LoadProblemFile(args[2]);
    if (!problem.ok()) return Fail(problem.status());
    if (command == "closed-loop") return ClosedLoop(client, *problem, json);
    absl::StatusOr<v1::SolveResult> r = client.SolveOnce(problem->spec);
    if (!r.ok()) return Fail(r.status());
    // A GP spec (no model) has one input.
    PrintResult(*r, problem->spec.has_gp() ? 1 : static_cast<int>(problem->spec.model().num_inputs()), json);
    return 0;
  }
  if (command == "fit-gp") {
    if (args.size() < 3) return nupmpc::cli::ReportUsageError(kProgram, "fit-gp: FILE missing");
    absl::StatusOr<v1::FitGpModelRequest> request = nupmpc::LoadJsonMessage<v1::FitGpModelRequest>(args[2]);
    if (!request.ok()) return Fail(request.status());
    absl::StatusOr<v1::FitGpModelResponse> fit = client.FitGpModel(*request);
    if (!fit.ok()) return Fail(fit.status());
    PrintJson(*fit, json);
    return 0;
  }
  if (command == "info") {
    absl::StatusOr<v1::GetServerInfoResponse> info = client.GetServerInfo();
    if (!info.ok()) return Fail(info.status());
    if (json) {
      PrintJson(*info, /*one_line=*/true);
    } else {
      std::fputs(nupmpc::ServerInfoTable(*info).c_str(), stdout);
    }
    return 0;
  }
  if (command == "sessions") {
    absl::StatusOr<std::vector<v1::SessionInfo>> sessions = client.ListSessions();
    if (!sessions.ok()) return Fail(sessions.status());
    for (const v1::SessionInfo& s : *sessions) {
      if (json) {
        std::string text;
        (void)google::protobuf::util::MessageToJsonString(s, &text);
        std::printf("%s\n", text.c_str());
      } else {
        std::printf("%s  M=%u L=%u K=%u N=%u  solves=%llu  idle=%.1fs%s\n", s.session_id().c_str(),
                    s.dimensions().num_states(), s.dimensions().num_inputs(), s.dimensions().num_outputs(),
                    s.dimensions().horizon(), static_cast<unsigned long long>(s.solves()), s.idle_s(),
                    s.attached() ? "  (stream attached)" : "");
      }
    }
    return 0;
  }
  return nupmpc::cli::ReportUsageError(kProgram, absl::StrCat("unknown command \"", command, "\""));
}
