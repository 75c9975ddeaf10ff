// nupmpc-fuzz-seeds DIR [INSTANCE.json...]: writes the seed corpora of the fuzz targets:
// DIR/spec_solve (serialized ProblemSpecs: the fuzz seed problem and the given instances),
// DIR/step (serialized Steps: states, prior updates, shifts, warm-start modes),
// DIR/control_stream (request sequences of one Control stream, tests/fuzz/control_sequence.h),
// DIR/problem_file (the instances' and the seed problem's JSON text) and DIR/snapshot (the
// seed session's core state, core::MpcSession::SaveState, after 0 to 3 solves).
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "client/problem_file.h"
#include "google/protobuf/util/json_util.h"
#include "server/sessions/call_context.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_solver.h"
#include "tests/fuzz/control_sequence.h"
#include "tests/fuzz/seed_problem.h"

namespace {

void Write(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// A stream that creates its session and steps through the seed states; the same read in
// lock-step, cancelled with steps in flight, attached to an unknown id, and attach-only
// followed by steps that update priors.
void WriteControlSequences(const std::filesystem::path& dir) {
  using nupmpc::v1::ControlRequest;
  std::vector<ControlRequest> steps;
  for (int k = 0; k < 4; ++k) {
    ControlRequest r;
    r.set_sequence(k + 1);
    *r.mutable_step() = nupmpc::fuzz::SeedStep(k);
    steps.push_back(r);
  }
  ControlRequest create;
  *create.mutable_spec() = nupmpc::fuzz::SeedSpec();
  nupmpc::fuzz::ControlSequence s;
  s.requests.push_back(create);
  s.requests.insert(s.requests.end(), steps.begin(), steps.end());
  Write(dir / "create_and_step", nupmpc::fuzz::EncodeControlSequence(s));
  s.lock_step = true;
  Write(dir / "lock_step", nupmpc::fuzz::EncodeControlSequence(s));
  s.lock_step = false;
  s.cancel_at_end = true;
  Write(dir / "cancel", nupmpc::fuzz::EncodeControlSequence(s));
  nupmpc::fuzz::ControlSequence unknown;
  ControlRequest attach = steps[0];
  attach.set_session_id("0123456789abcdef0123456789abcdef");
  unknown.requests.push_back(attach);
  unknown.requests.push_back(steps[1]);
  Write(dir / "unknown_id", nupmpc::fuzz::EncodeControlSequence(unknown));
  nupmpc::fuzz::ControlSequence updates;
  updates.requests.push_back(create);
  for (ControlRequest r : steps) {
    auto* e = r.mutable_step()->mutable_update()->add_inputs();
    e->set_index(0);
    e->mutable_prior()->set_kind(nupmpc::v1::PRIOR_KIND_BOX);
    e->mutable_prior()->add_weight(1.0);
    e->mutable_prior()->add_lower(-0.2);
    e->mutable_prior()->add_upper(0.2);
    r.mutable_step()->mutable_update()->set_shift(true);
    updates.requests.push_back(r);
  }
  Write(dir / "updates", nupmpc::fuzz::EncodeControlSequence(updates));
}

// The seed session's state as a fresh session and after each of three solves.
void WriteSnapshotStates(const std::filesystem::path& dir) {
  nupmpc::server::CallContext call;
  absl::StatusOr<nupmpc::server::BuiltSession> built =
      nupmpc::server::BuildSession(nupmpc::fuzz::SeedSpec(), nupmpc::server::SizeLimits(), nullptr, &call);
  if (!built.ok()) return;
  nupmpc::server::SessionEntry entry;
  entry.solver = std::move(built->solver);
  entry.timing = built->timing;
  for (int k = 0; k < 4; ++k) {
    std::string state;
    if (entry.solver->SaveState(&state).ok()) Write(dir / ("after" + std::to_string(k)), state);
    nupmpc::v1::SolveResult result;
    (void)nupmpc::server::SolveStep(entry, nupmpc::fuzz::SeedStep(k), call, &result);
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: nupmpc-fuzz-seeds DIR [INSTANCE.json...]\n");
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  for (const char* sub : {"spec_solve", "step", "control_stream", "problem_file", "snapshot"})
    std::filesystem::create_directories(dir / sub);
  const nupmpc::v1::ProblemSpec seed = nupmpc::fuzz::SeedSpec();
  Write(dir / "spec_solve" / "seed", seed.SerializeAsString());
  std::string json;
  (void)google::protobuf::util::MessageToJsonString(seed, &json);
  Write(dir / "problem_file" / "seed.json", json);
  for (int i = 2; i < argc; ++i) {
    const std::filesystem::path path = argv[i];
    absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(path.string());
    if (!file.ok()) continue;
    Write(dir / "spec_solve" / path.stem(), file->spec.SerializeAsString());
    std::ifstream in(path);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.size() < 200'000) Write(dir / "problem_file" / path.filename(), text);
  }
  for (int k = 0; k < 4; ++k) {
    nupmpc::v1::Step step = nupmpc::fuzz::SeedStep(k);
    Write(dir / "step" / ("state" + std::to_string(k)), step.SerializeAsString());
    nupmpc::v1::Step update = step;
    auto* e = update.mutable_update()->add_outputs();
    e->set_index(k % 4);
    e->mutable_prior()->set_kind(nupmpc::v1::PRIOR_KIND_BOX);
    e->mutable_prior()->add_weight(1.0);
    e->mutable_prior()->add_lower(-1.0 - k);
    e->mutable_prior()->add_upper(1.0 + k);
    update.mutable_update()->set_shift(k % 2 == 1);
    update.set_warm_start(k % 2 == 0 ? nupmpc::v1::WARM_START_KEEP : nupmpc::v1::WARM_START_COLD);
    Write(dir / "step" / ("update" + std::to_string(k)), update.SerializeAsString());
  }
  WriteControlSequences(dir / "control_stream");
  WriteSnapshotStates(dir / "snapshot");
  return 0;
}
