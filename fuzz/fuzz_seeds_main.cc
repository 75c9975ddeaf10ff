// nupmpc-fuzz-seeds DIR [INSTANCE.json...]: writes the seed corpora of the fuzz targets:
// DIR/spec_solve (serialized ProblemSpecs: the fuzz seed problem and the given instances),
// DIR/step (serialized Steps: states, prior updates, shifts, warm-start modes) and
// DIR/problem_file (the instances' and the seed problem's JSON text).
#include <filesystem>
#include <fstream>
#include <string>

#include "client/problem_file.h"
#include "fuzz/seed_problem.h"
#include "google/protobuf/util/json_util.h"

namespace {

void Write(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: nupmpc-fuzz-seeds DIR [INSTANCE.json...]\n");
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  for (const char* sub : {"spec_solve", "step", "problem_file"}) std::filesystem::create_directories(dir / sub);
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
  return 0;
}
