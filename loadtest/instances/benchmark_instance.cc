#include "loadtest/instances/benchmark_instance.h"

#include <fstream>

#include "absl/strings/str_cat.h"
#include "client/problem_file.h"
#include "nlohmann/json.hpp"

namespace nupmpc::bench {
namespace {

using json = nlohmann::json;

absl::StatusOr<json> ReadJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", e.what()));
  }
}

Eigen::MatrixXd Matrix(const json& j) {
  const int rows = static_cast<int>(j.size());
  const int cols = rows == 0 ? 0 : static_cast<int>(j[0].size());
  Eigen::MatrixXd m(rows, cols);
  for (int i = 0; i < rows; ++i) {
    for (int k = 0; k < cols; ++k) m(i, k) = j[i][k].get<double>();
  }
  return m;
}

Eigen::VectorXd Vector(const json& j) {
  Eigen::VectorXd v(j.size());
  for (std::size_t i = 0; i < j.size(); ++i) v(static_cast<Eigen::Index>(i)) = j[i].get<double>();
  return v;
}

}  // namespace

server::SizeLimits NoSizeLimits() {
  server::SizeLimits limits;
  limits.max_states = limits.max_inputs = limits.max_outputs = 1 << 20;
  limits.max_horizon = limits.max_iterations = limits.max_gp_points = 1 << 30;
  limits.max_input_levels = limits.max_keep_out_regions = 1 << 20;
  limits.max_scalars = 1LL << 40;
  limits.max_session_bytes = 1LL << 50;
  limits.max_pass_flops = 1e30;
  return limits;
}

absl::StatusOr<BenchmarkInstance> LoadBenchmarkInstance(const std::string& path) {
  absl::StatusOr<ProblemFile> file = LoadBenchmarkInstanceSpec(path);
  if (!file.ok()) return file.status();
  absl::StatusOr<core::Problem> problem = server::ProblemFromSpec(file->spec, NoSizeLimits());
  if (!problem.ok()) return absl::Status(problem.status().code(), absl::StrCat(path, ": ", problem.status().message()));
  BenchmarkInstance inst;
  inst.name = std::move(file->name);
  inst.family = std::move(file->family);
  inst.problem = *std::move(problem);
  if (!file->closed_loop_states.empty()) {
    BenchmarkInstance::ClosedLoop cl;
    for (const std::vector<double>& x : file->closed_loop_states) {
      cl.x1.push_back(Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(x.size())));
    }
    inst.closed_loop = std::move(cl);
  }
  return inst;
}

absl::StatusOr<std::map<std::string, Reference>> LoadReferences(const std::string& path) {
  absl::StatusOr<json> doc = ReadJson(path);
  if (!doc.ok()) return doc.status();
  std::map<std::string, Reference> refs;
  try {
    for (const auto& [name, e] : doc->at("instances").items()) {
      Reference r;
      r.J_star = e.at("J_star").get<double>();
      r.max_violation = e.value("max_violation", 0.0);
      if (e.contains("u_star")) r.u_star = Matrix(e["u_star"]);
      if (e.contains("x1_star")) r.x1_star = Vector(e["x1_star"]);
      if (e.contains("closed_loop")) {
        for (const json& j : e["closed_loop"].at("J_star")) r.closed_loop_J_star.push_back(j.get<double>());
        if (e["closed_loop"].contains("u_star")) {
          for (const json& u : e["closed_loop"]["u_star"]) r.closed_loop_u_star.push_back(Matrix(u));
        }
      }
      refs.emplace(name, std::move(r));
    }
  } catch (const json::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": malformed reference file: ", e.what()));
  }
  return refs;
}

}  // namespace nupmpc::bench
