#include "client/problem_file.h"

#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "google/protobuf/util/json_util.h"
#include "loadtest/benchmark_instance.h"
#include "server/spec_conversion.h"

namespace nupmpc {

absl::StatusOr<std::string> ReadTextFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

absl::StatusOr<ProblemFile> LoadProblemFile(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  ProblemFile out;
  if (text->find("\"dims\"") != std::string::npos) {  // the benchmark format
    absl::StatusOr<bench::BenchmarkInstance> instance = bench::LoadBenchmarkInstance(path);
    if (!instance.ok()) return instance.status();
    absl::StatusOr<v1::ProblemSpec> spec = server::SpecFromProblem(instance->problem);
    if (!spec.ok()) return spec.status();
    out.spec = *std::move(spec);
    if (instance->closed_loop.has_value()) {
      for (const Eigen::VectorXd& x : instance->closed_loop->x1) out.closed_loop_states.emplace_back(x.begin(), x.end());
    }
    return out;
  }
  const auto status = google::protobuf::util::JsonStringToMessage(*text, &out.spec);
  if (!status.ok()) return absl::InvalidArgumentError(absl::StrCat(path, ": not a ProblemSpec: ", status.ToString()));
  return out;
}

}  // namespace nupmpc
