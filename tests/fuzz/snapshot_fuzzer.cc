// Fuzz target (e): the session snapshot reader. Every input is read twice:
//  * as a file found in --state_dir: Unseal must refuse it or read it, never crash;
//  * as the core state inside a snapshot sealed like a server seals one (so the input
//    passes the integrity check and reaches the core's reader): it is restored into a
//    session built from the fuzz seed spec and, when the restore is accepted, solved once
//    (at most 20 passes, 500 ms).
// Properties: no crash, hang or sanitizer report; a refused restore says what it refused.
// The seeds are real snapshots of the seed session (nupmpc-fuzz-seeds), so mutations of
// valid states are explored, not only garbage.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "absl/strings/string_view.h"
#include "server/sessions/call_context.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_solver.h"
#include "server/snapshots/sealed_snapshot.h"
#include "tests/fuzz/fuzz_limits.h"
#include "tests/fuzz/seed_problem.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using nupmpc::server::SnapshotKey;
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  constexpr std::size_t kMaxBytes = 1 << 20;
  (void)nupmpc::server::Unseal(bytes, SnapshotKey(), kMaxBytes);

  static const SnapshotKey key = *SnapshotKey::FromBytes(std::string(32, 'k'));
  nupmpc::snapshot::v1::SessionSnapshot snapshot;
  snapshot.set_format_version(nupmpc::server::kSnapshotFormatVersion);
  snapshot.set_session_id("0123456789abcdef0123456789abcdef");
  *snapshot.mutable_spec() = nupmpc::fuzz::SeedSpec();
  snapshot.set_core_state(std::string(bytes));
  absl::StatusOr<nupmpc::snapshot::v1::SessionSnapshot> unsealed =
      nupmpc::server::Unseal(nupmpc::server::Seal(snapshot, key), key, 2 * kMaxBytes);
  if (!unsealed.ok()) nupmpc::fuzz::Violated("a sealed snapshot is refused");

  nupmpc::server::CallContext call;
  absl::StatusOr<nupmpc::server::BuiltSession> built =
      nupmpc::server::BuildSession(unsealed->spec(), nupmpc::fuzz::SmallLimits(), nullptr, &call);
  if (!built.ok()) nupmpc::fuzz::Violated("the seed spec does not build");
  const absl::Status restored = built->solver->RestoreState(unsealed->core_state());
  if (!restored.ok()) {
    if (restored.message().empty()) nupmpc::fuzz::Violated("a refused restore without a message");
    return 0;
  }
  nupmpc::server::SessionEntry entry;
  entry.solver = std::move(built->solver);
  entry.timing = built->timing;
  nupmpc::v1::Step step = nupmpc::fuzz::SeedStep(1);
  step.set_max_iterations(20);
  call.deadline = nupmpc::server::Clock::now() + std::chrono::milliseconds(500);
  nupmpc::v1::SolveResult result;
  (void)nupmpc::server::SolveStep(entry, step, call, &result);
  return 0;
}
