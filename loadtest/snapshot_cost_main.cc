// nupmpc-snapshot-cost: what session snapshots (--state_dir) cost and what they save, for
// each session kind of an instance (loadtest/instances/session_kinds.h):
//  * the bytes of one sealed snapshot;
//  * the first step after a hand-over: its passes and plan for the session restored from
//    its snapshot and for the session re-created cold from its spec (what clients did
//    before snapshots), each next to the never-moved twin's;
//  * writing and restoring many sessions (--sessions, the first kind): the time a drain
//    spends writing them, and the time replicas spend restoring them.
// Everything runs in this process through the server's own code (server/snapshots/,
// ServerState), against a temporary state directory.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "cli/program_flags.h"
#include "client/problem_file.h"
#include "loadtest/instances/session_kinds.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_solver.h"
#include "server/snapshots/sealed_snapshot.h"
#include "server/snapshots/session_snapshot.h"
#include "server/state/server_state.h"

ABSL_FLAG(std::string, instance, "benchmarks/masses_N30.json", "the sessions' problem");
ABSL_FLAG(int, steps, 5, "closed-loop steps before the hand-over");
ABSL_FLAG(int, sessions, 10000, "sessions written and restored in bulk");

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-snapshot-cost",
    .summary =
        "nupmpc-snapshot-cost: session snapshot bytes per session kind, the first step after a hand-over "
        "(restored vs re-created cold), and the time to write and restore many sessions",
    .usage = "nupmpc-snapshot-cost [--instance FILE] [--steps N] [--sessions N]",
    .max_arguments = 0,
};

// A server's state with its own state directory, removed at the end.
struct Replica {
  explicit Replica(const std::string& dir, int max_sessions) : state(Options(dir, max_sessions)) {
    nupmpc::server::SnapshotStoreOptions store;
    store.dir = dir;
    store.max_snapshot_bytes = std::size_t{1} << 30;
    store.reattach_window_s = 3600;
    state.snapshots = *nupmpc::server::SnapshotStore::Open(store);
  }
  static nupmpc::server::ServerOptions Options(const std::string& dir, int max_sessions) {
    nupmpc::server::ServerOptions o;
    o.state_dir = dir;
    o.max_sessions = max_sessions;
    o.memory_budget_bytes = std::int64_t{16} << 30;
    return o;
  }
  std::shared_ptr<nupmpc::server::SessionEntry> Create(const nupmpc::v1::ProblemSpec& spec) {
    nupmpc::server::CallContext call;
    absl::StatusOr<std::shared_ptr<nupmpc::server::SessionEntry>> entry = nupmpc::server::CreateAndRegister(
        spec, state.options.size_limits, &state.gp_models, &state.budget, &state.registry, call, false, {}, {},
        /*keep_spec=*/true);
    if (!entry.ok()) {
      std::fprintf(stderr, "nupmpc-snapshot-cost: %s\n", std::string(entry.status().message()).c_str());
      std::exit(1);
    }
    return *entry;
  }
  nupmpc::server::ServerState state;
};

nupmpc::v1::SolveResult Step(nupmpc::server::SessionEntry& entry, const std::vector<double>& x) {
  nupmpc::v1::Step step;
  step.mutable_state()->Assign(x.begin(), x.end());
  nupmpc::server::CallContext call;
  nupmpc::v1::SolveResult result;
  if (const absl::Status s = nupmpc::server::SolveStep(entry, step, call, &result); !s.ok()) {
    std::fprintf(stderr, "nupmpc-snapshot-cost: %s\n", std::string(s.message()).c_str());
    std::exit(1);
  }
  return result;
}

std::vector<double> NextState(const nupmpc::v1::SolveResult& result, int m) {
  return {result.states().begin() + m, result.states().begin() + 2 * m};
}

double MaxInputDifference(const nupmpc::v1::SolveResult& a, const nupmpc::v1::SolveResult& b) {
  if (a.inputs_size() != b.inputs_size()) return INFINITY;
  double d = 0.0;
  for (int i = 0; i < a.inputs_size(); ++i) d = std::max(d, std::abs(a.inputs(i) - b.inputs(i)));
  return d;
}

}  // namespace

int main(int argc, char** argv) {
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(absl::GetFlag(FLAGS_instance));
  if (!file.ok()) return nupmpc::cli::ReportUsageError(kProgram, file.status().message());
  const int steps = std::max(1, absl::GetFlag(FLAGS_steps));
  const int sessions = std::max(1, absl::GetFlag(FLAGS_sessions));
  const std::string root = absl::StrCat("/tmp/nupmpc-snapshot-cost.", getpid());
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root);
  const auto kinds = nupmpc::bench::SessionKindsOf(file->spec);

  std::printf("instance %s, %d closed-loop steps before the hand-over\n", file->name.c_str(), steps);
  std::printf("%-18s %14s %28s %30s\n", "kind", "snapshot bytes", "first step's passes: twin /",
              "max |u - u_twin|: restored /");
  std::printf("%-18s %14s %28s %30s\n", "", "", "restored / re-created cold", "re-created cold");
  for (std::size_t k = 0; k < kinds.size(); ++k) {
    const nupmpc::v1::ProblemSpec& spec = kinds[k].spec;
    const int m = static_cast<int>(spec.model().num_states());
    Replica from(absl::StrCat(root, "/from", k), 4), to(absl::StrCat(root, "/to", k), 4);
    std::shared_ptr<nupmpc::server::SessionEntry> twin = from.Create(spec);
    std::vector<double> x(spec.initial_state().mean().begin(), spec.initial_state().mean().end());
    for (int s = 0; s < steps; ++s) x = NextState(Step(*twin, x), m);
    absl::StatusOr<nupmpc::snapshot::v1::SessionSnapshot> snapshot = nupmpc::server::TakeSnapshot(*twin);
    if (!snapshot.ok()) {
      std::printf("%-18s no snapshot: %s\n", kinds[k].name.c_str(), std::string(snapshot.status().message()).c_str());
      continue;
    }
    const std::size_t bytes = nupmpc::server::Seal(*snapshot, nupmpc::server::SnapshotKey()).size();
    absl::StatusOr<std::shared_ptr<nupmpc::server::SessionEntry>> restored = nupmpc::server::RestoreSnapshot(
        *snapshot, to.state.options.size_limits, &to.state.gp_models, &to.state.budget, &to.state.registry);
    if (!restored.ok()) {
      std::printf("%-18s not restored: %s\n", kinds[k].name.c_str(), std::string(restored.status().message()).c_str());
      continue;
    }
    std::shared_ptr<nupmpc::server::SessionEntry> cold = to.Create(spec);
    const nupmpc::v1::SolveResult after_twin = Step(*twin, x), after_restored = Step(**restored, x),
                                  after_cold = Step(*cold, x);
    std::printf("%-18s %14zu %16u / %u / %u %20.3g / %.3g\n", kinds[k].name.c_str(), bytes, after_twin.iterations(),
                after_restored.iterations(), after_cold.iterations(), MaxInputDifference(after_restored, after_twin),
                MaxInputDifference(after_cold, after_twin));
  }

  // Bulk: a drain writing every session, replicas restoring them.
  {
    const std::string dir = absl::StrCat(root, "/bulk");
    Replica draining(dir, sessions + 1);
    const nupmpc::v1::ProblemSpec& spec = kinds.front().spec;
    std::vector<double> x(spec.initial_state().mean().begin(), spec.initial_state().mean().end());
    std::vector<std::string> ids;
    for (int i = 0; i < sessions; ++i) {
      std::shared_ptr<nupmpc::server::SessionEntry> entry = draining.Create(spec);
      Step(*entry, x);
      ids.push_back(entry->id);
    }
    const auto write_start = Clock::now();
    const int written = draining.state.WriteSnapshots(nupmpc::server::Clock::now() + std::chrono::minutes(10));
    const double write_s = Seconds(Clock::now() - write_start);
    std::uintmax_t total_bytes = 0;
    for (const auto& f : std::filesystem::directory_iterator(dir)) total_bytes += f.file_size();
    Replica restoring(dir, sessions + 1);
    const auto restore_start = Clock::now();
    int restored = 0;
    for (const std::string& id : ids)
      restored += restoring.state.FindOrRestore(id, {}, /*by_control_stream=*/true).ok() ? 1 : 0;
    const double restore_s = Seconds(Clock::now() - restore_start);
    std::printf("%d %s sessions: written in %.3f s (%.1f us each, %.1f MB), restored %d in %.3f s (%.1f us each)\n",
                written, kinds.front().name.c_str(), write_s, write_s / std::max(written, 1) * 1e6,
                static_cast<double>(total_bytes) / 1e6, restored, restore_s, restore_s / std::max(restored, 1) * 1e6);
  }
  std::filesystem::remove_all(root);
  return 0;
}
