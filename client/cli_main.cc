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
// FILE is an instance in the ../shared/benchmarks format or a ProblemSpec in proto JSON.
// --format table|json; with json, closed-loop prints one object per step and line with
// step, objective, iterations, solve_ms, round_trip_ms, status, max_violation, u0, then
// one summary object ("summary": true); with table, a summary after the steps.
#include <cstdio>
#include <random>
#include <string>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "cli/program_flags.h"
#include "client/client.h"
#include "client/closed_loop_summary.h"
#include "client/problem_file.h"
#include "client/server_info_table.h"
#include "client/solve_status_name.h"
#include "google/protobuf/util/json_util.h"

ABSL_FLAG(std::string, server, "localhost:50051", "server address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(std::string, format, "table", "table or json");
ABSL_FLAG(int, steps, 0, "closed-loop: number of steps (0: the instance's sequence, or 50)");
ABSL_FLAG(double, noise, 0.0, "closed-loop simulation: std. dev. of additive state noise");
ABSL_FLAG(int, seed, 1, "closed-loop simulation: noise seed");
ABSL_FLAG(int, deadline_ms, 0, "deadline of unary calls (0: none)");

namespace {

namespace v1 = nupmpc::v1;
using nupmpc::SolveStatusName;

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc",
    .summary = "nupmpc: command-line client of nupmpc-server.\n"
               "  solve FILE        one stateless solve (SolveOnce)\n"
               "  closed-loop FILE  a receding-horizon run through a Control stream: the instance's recorded\n"
               "                    closed-loop states if it has them, else the model simulated locally\n"
               "                    (--noise); ends with a summary (convergence, solve and round-trip times)\n"
               "  fit-gp FILE       GP hyper-parameters by maximum likelihood (FitGpModel); FILE is a\n"
               "                    FitGpModelRequest in proto JSON\n"
               "  info              server version, CPU baseline, limits, counters\n"
               "  sessions          open sessions\n"
               "FILE is an instance in the ../shared/benchmarks format or a ProblemSpec in proto JSON.",
    .usage = "nupmpc [--server HOST:PORT] [--format table|json] solve FILE | closed-loop FILE | fit-gp FILE | info | "
             "sessions",
    .environment = {{"NUPMPC_SERVER", "server address when --server is not given"}},
    .max_arguments = 2,
};

std::string U0(const v1::SolveResult& r, int L) {
  std::vector<std::string> parts;
  for (int l = 0; l < L && l < r.inputs_size(); ++l) parts.push_back(absl::StrCat(r.inputs(l)));
  return absl::StrCat("[", absl::StrJoin(parts, ","), "]");
}

void PrintResult(const v1::SolveResult& r, int L, bool json) {
  if (json) {
    std::printf("{\"status\":\"%s\",\"objective\":%.17g,\"iterations\":%u,\"solve_ms\":%.6f,\"max_violation\":%.6g,"
                "\"u0\":%s}\n",
                SolveStatusName(r.status()).c_str(), r.objective(), r.iterations(), r.solve_ms(), r.max_violation(),
                U0(r, L).c_str());
  } else {
    std::printf("status %s, %u iterations, %.4f ms, J = %.12g, max violation %.3g\nu[0] = %s\n",
                SolveStatusName(r.status()).c_str(), r.iterations(), r.solve_ms(), r.objective(), r.max_violation(),
                U0(r, L).c_str());
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

// x ← A x + B u0 (+ c) (+ noise), from the spec's first (time-invariant) matrices.
std::vector<double> Simulate(const v1::ProblemSpec& spec, const std::vector<double>& x, const v1::SolveResult& r,
                             std::normal_distribution<double>& noise, std::mt19937_64& rng) {
  const v1::Model& m = spec.model();
  const int M = static_cast<int>(m.num_states()), L = static_cast<int>(m.num_inputs());
  std::vector<double> next(M, 0.0);
  for (int i = 0; i < M; ++i) {
    for (int j = 0; j < M; ++j) next[i] += m.a(0).data(i * M + j) * x[j];
    for (int l = 0; l < L; ++l) next[i] += m.b(0).data(i * L + l) * r.inputs(l);
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
  absl::StatusOr<std::unique_ptr<nupmpc::Session>> session = client.OpenSession(problem.spec);
  if (!session.ok()) return Fail(session.status());
  const int L = static_cast<int>(problem.spec.model().num_inputs());
  const bool recorded = !problem.closed_loop_states.empty();
  int steps = absl::GetFlag(FLAGS_steps);
  if (steps <= 0) steps = recorded ? static_cast<int>(problem.closed_loop_states.size()) : 50;
  if (recorded) steps = std::min<int>(steps, problem.closed_loop_states.size());
  std::mt19937_64 rng(absl::GetFlag(FLAGS_seed));
  std::normal_distribution<double> noise(0.0, absl::GetFlag(FLAGS_noise));
  std::vector<double> x(problem.spec.initial_state().mean().begin(), problem.spec.initial_state().mean().end());
  if (!json) std::printf("%5s %-16s %6s %10s %10s %18s %10s  %s\n", "step", "status", "iter", "solve_ms", "rtt_ms",
                         "objective", "max_viol", "u0");
  std::vector<nupmpc::ClosedLoopStep> record;
  for (int t = 0; t < steps; ++t) {
    if (recorded) x = problem.closed_loop_states[t];
    v1::Step step;
    step.mutable_state()->Add(x.begin(), x.end());
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<v1::SolveResult> r = (*session)->Step(step);
    const double rtt_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!r.ok()) return Fail(r.status());
    record.push_back({r->status(), r->solve_ms(), rtt_ms, r->max_violation()});
    if (json) {
      std::printf("{\"step\":%d,\"status\":\"%s\",\"objective\":%.17g,\"iterations\":%u,\"solve_ms\":%.6f,"
                  "\"round_trip_ms\":%.6f,\"max_violation\":%.6g,\"warm_started\":%s,\"u0\":%s}\n",
                  t, SolveStatusName(r->status()).c_str(), r->objective(), r->iterations(), r->solve_ms(), rtt_ms,
                  r->max_violation(), r->warm_started() ? "true" : "false", U0(*r, L).c_str());
    } else {
      std::printf("%5d %-16s %6u %10.4f %10.4f %18.10g %10.3g  %s\n", t, SolveStatusName(r->status()).c_str(),
                  r->iterations(), r->solve_ms(), rtt_ms, r->objective(), r->max_violation(), U0(*r, L).c_str());
    }
    std::fflush(stdout);
    if (!recorded) x = Simulate(problem.spec, x, *r, noise, rng);
  }
  if (absl::Status s = (*session)->Close(); !s.ok()) return Fail(s);
  const nupmpc::ClosedLoopSummary summary = nupmpc::SummariseClosedLoop(record);
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
  nupmpc::Client client(absl::GetFlag(FLAGS_server), std::chrono::milliseconds(absl::GetFlag(FLAGS_deadline_ms)));

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
