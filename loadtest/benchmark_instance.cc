#include "loadtest/benchmark_instance.h"

#include <fstream>

#include "absl/strings/str_cat.h"
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

// Bound entry (n, i) of an optional N×dim array of numbers or nulls.
std::optional<double> Bound(const json& doc, const char* field, int n, int i) {
  if (!doc.contains(field) || doc[field].is_null()) return std::nullopt;
  const json& e = doc[field][n][i];
  if (e.is_null()) return std::nullopt;
  return e.get<double>();
}

core::ScalarPrior BoundedPrior(std::optional<double> lo, std::optional<double> hi) {
  if (lo && hi) return core::ScalarPrior::Box(*lo, *hi);
  if (lo) return core::ScalarPrior::AtLeast(*lo);
  if (hi) return core::ScalarPrior::AtMost(*hi);
  return core::ScalarPrior::Free();
}

absl::Status RequireDiagonal(const Eigen::MatrixXd& m, const char* field) {
  Eigen::MatrixXd off = m;
  off.diagonal().setZero();
  if (!off.isZero(0.0)) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": only diagonal weights are supported"));
  }
  return absl::OkStatus();
}

absl::StatusOr<BenchmarkInstance> Convert(const json& doc) {
  BenchmarkInstance inst;
  inst.name = doc.value("name", "");
  inst.family = doc.value("family", "");
  const json& dims = doc.at("dims");
  const int M = dims.at("M"), L = dims.at("L"), K = dims.at("K"), N = dims.at("N");
  core::Problem p = core::Problem::TimeInvariant(M, L, K, N);
  p.A = {Matrix(doc.at("A"))};
  p.B = {Matrix(doc.at("B"))};
  p.C = {Matrix(doc.at("C"))};
  if (doc.contains("x1")) {
    p.initial_mean = Vector(doc["x1"]);
  } else {
    p.initial_mean = Vector(doc.at("x1_prior").at("mean"));
    p.initial_covariance = Matrix(doc["x1_prior"].at("cov"));
  }
  Eigen::VectorXd input_weight = Eigen::VectorXd::Zero(L), u_ref = Eigen::VectorXd::Zero(L);
  if (doc.contains("R")) {
    const Eigen::MatrixXd R = Matrix(doc["R"]);
    if (absl::Status s = RequireDiagonal(R, "R"); !s.ok()) return s;
    input_weight = R.diagonal();
  }
  if (doc.contains("u_ref")) u_ref = Vector(doc["u_ref"]);
  Eigen::VectorXd output_weight = Eigen::VectorXd::Zero(K);
  if (doc.contains("Qy")) {
    const Eigen::MatrixXd Qy = Matrix(doc["Qy"]);
    if (absl::Status s = RequireDiagonal(Qy, "Qy"); !s.ok()) return s;
    output_weight = Qy.diagonal();
  }
  for (int n = 0; n < N; ++n) {
    for (int l = 0; l < L; ++l) {
      core::ScalarPrior prior = BoundedPrior(Bound(doc, "u_min", n, l), Bound(doc, "u_max", n, l));
      if (input_weight(l) > 0.0) prior = prior.WithGaussian(u_ref(l), 1.0 / input_weight(l));
      p.mutable_input_prior(n, l) = prior;
    }
    for (int k = 0; k < K; ++k) {
      core::ScalarPrior prior = BoundedPrior(Bound(doc, "y_min", n, k), Bound(doc, "y_max", n, k));
      if (output_weight(k) > 0.0) {
        const double ref = doc.contains("y_ref") ? doc["y_ref"][n][k].get<double>() : 0.0;
        prior = prior.WithGaussian(ref, 1.0 / output_weight(k));
      }
      p.mutable_output_prior(n, k) = prior;
    }
  }
  if (doc.contains("Qf")) {
    core::Problem::Terminal t;
    t.weight = Matrix(doc["Qf"]);
    t.target = doc.contains("x_f") ? Vector(doc["x_f"]) : Eigen::VectorXd::Zero(M);
    p.terminal = t;
  }
  inst.problem = std::move(p);
  if (doc.contains("closed_loop")) {
    BenchmarkInstance::ClosedLoop cl;
    for (const json& x : doc["closed_loop"].at("x1")) cl.x1.push_back(Vector(x));
    inst.closed_loop = std::move(cl);
  }
  return inst;
}

}  // namespace

absl::StatusOr<BenchmarkInstance> LoadBenchmarkInstance(const std::string& path) {
  absl::StatusOr<json> doc = ReadJson(path);
  if (!doc.ok()) return doc.status();
  try {
    absl::StatusOr<BenchmarkInstance> inst = Convert(*doc);
    if (!inst.ok()) return absl::Status(inst.status().code(), absl::StrCat(path, ": ", inst.status().message()));
    return inst;
  } catch (const json::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": malformed instance: ", e.what()));
  }
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
