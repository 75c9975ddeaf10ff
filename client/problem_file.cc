#include "client/problem_file.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "google/protobuf/struct.pb.h"
#include "google/protobuf/util/json_util.h"

namespace nupmpc {
namespace {

using google::protobuf::ListValue;
using google::protobuf::Struct;
using google::protobuf::Value;

constexpr double kInf = std::numeric_limits<double>::infinity();

absl::Status Malformed(const std::string& field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", what));
}

// The member `name` of an object; nullptr when absent or null.
const Value* Member(const Struct& object, const std::string& name) {
  const auto it = object.fields().find(name);
  if (it == object.fields().end() || it->second.kind_case() == Value::kNullValue) return nullptr;
  return &it->second;
}

absl::StatusOr<const Value*> Required(const Struct& object, const std::string& name) {
  const Value* v = Member(object, name);
  if (v == nullptr) return Malformed(name, "required");
  return v;
}

absl::StatusOr<const ListValue*> List(const Value& v, const std::string& field) {
  if (v.kind_case() != Value::kListValue) return Malformed(field, "expected a list");
  return &v.list_value();
}

absl::StatusOr<double> Number(const Value& v, const std::string& field) {
  if (v.kind_case() != Value::kNumberValue) return Malformed(field, "expected a number");
  return v.number_value();
}

absl::StatusOr<int> Count(const Struct& object, const std::string& name, const std::string& field) {
  absl::StatusOr<const Value*> v = Required(object, name);
  if (!v.ok()) return Malformed(field, "required");
  absl::StatusOr<double> x = Number(**v, field);
  if (!x.ok()) return x.status();
  if (!(*x >= 0.0 && *x <= 1e9 && std::floor(*x) == *x)) return Malformed(field, "expected a count");
  return static_cast<int>(*x);
}

absl::Status Numbers(const Value& v, const std::string& field, google::protobuf::RepeatedField<double>* out) {
  absl::StatusOr<const ListValue*> list = List(v, field);
  if (!list.ok()) return list.status();
  for (int i = 0; i < (*list)->values_size(); ++i) {
    absl::StatusOr<double> x = Number((*list)->values(i), absl::StrCat(field, "[", i, "]"));
    if (!x.ok()) return x.status();
    out->Add(*x);
  }
  return absl::OkStatus();
}

// A row-major nested list as a v1::Matrix of its own shape (the conversion checks it
// against the model's dimensions).
absl::Status ReadMatrix(const Value& v, const std::string& field, v1::Matrix* out) {
  absl::StatusOr<const ListValue*> rows = List(v, field);
  if (!rows.ok()) return rows.status();
  out->set_rows(static_cast<unsigned>((*rows)->values_size()));
  out->set_cols(0);
  for (int i = 0; i < (*rows)->values_size(); ++i) {
    const std::string row_field = absl::StrCat(field, "[", i, "]");
    const int before = out->data_size();
    if (absl::Status s = Numbers((*rows)->values(i), row_field, out->mutable_data()); !s.ok()) return s;
    const int cols = out->data_size() - before;
    if (i == 0) out->set_cols(static_cast<unsigned>(cols));
    if (cols != static_cast<int>(out->cols())) return Malformed(row_field, "rows of different lengths");
  }
  return absl::OkStatus();
}

// The diagonal of a square weight matrix; INVALID_ARGUMENT when it has off-diagonal entries.
absl::StatusOr<std::vector<double>> Diagonal(const Value& v, const std::string& field, int size) {
  v1::Matrix m;
  if (absl::Status s = ReadMatrix(v, field, &m); !s.ok()) return s;
  if (static_cast<int>(m.rows()) != size || static_cast<int>(m.cols()) != size) {
    return Malformed(field, absl::StrCat("expected ", size, "x", size));
  }
  std::vector<double> diagonal(static_cast<std::size_t>(size));
  for (int i = 0; i < size; ++i) {
    for (int j = 0; j < size; ++j) {
      const double x = m.data(i * size + j);
      if (i == j)
        diagonal[static_cast<std::size_t>(i)] = x;
      else if (x != 0.0)
        return Malformed(field, "only diagonal weights are supported");
    }
  }
  return diagonal;
}

// An optional N×dim array of numbers or nulls (null: no bound at that entry).
class BoundTable {
 public:
  static absl::StatusOr<BoundTable> Read(const Struct& doc, const std::string& name, int steps, int dim) {
    BoundTable table;
    const Value* v = Member(doc, name);
    if (v == nullptr) return table;
    absl::StatusOr<const ListValue*> rows = List(*v, name);
    if (!rows.ok()) return rows.status();
    if ((*rows)->values_size() < steps) return Malformed(name, absl::StrCat("expected ", steps, " rows"));
    table.entries_.assign(static_cast<std::size_t>(steps) * dim, std::nullopt);
    for (int n = 0; n < steps; ++n) {
      const std::string row_field = absl::StrCat(name, "[", n, "]");
      absl::StatusOr<const ListValue*> row = List((*rows)->values(n), row_field);
      if (!row.ok()) return row.status();
      if ((*row)->values_size() < dim) return Malformed(row_field, absl::StrCat("expected ", dim, " entries"));
      for (int i = 0; i < dim; ++i) {
        const Value& e = (*row)->values(i);
        if (e.kind_case() == Value::kNullValue) continue;
        absl::StatusOr<double> x = Number(e, absl::StrCat(row_field, "[", i, "]"));
        if (!x.ok()) return x.status();
        table.entries_[static_cast<std::size_t>(n) * dim + i] = *x;
      }
      table.dim_ = dim;
    }
    return table;
  }
  std::optional<double> at(int n, int i) const {
    if (entries_.empty()) return std::nullopt;
    return entries_[static_cast<std::size_t>(n) * dim_ + i];
  }

 private:
  std::vector<std::optional<double>> entries_;
  int dim_ = 0;
};

// One scalar's prior at one step: optional bounds and a quadratic part (weight > 0).
struct StepPrior {
  std::optional<double> lower, upper;
  double weight = 0.0, target = 0.0;
};

// One component's ComponentPrior from its per-step priors: one kind for the horizon (a
// bound that is absent at some steps, or changes side, makes a BOX with infinite sides
// there); per-step arrays that are constant become one value.
v1::ComponentPrior Component(const std::vector<StepPrior>& steps) {
  bool any_lower = false, any_upper = false, any_both = false, absent_somewhere = false;
  for (const StepPrior& p : steps) {
    any_lower |= p.lower.has_value() && !p.upper.has_value();
    any_upper |= p.upper.has_value() && !p.lower.has_value();
    any_both |= p.lower.has_value() && p.upper.has_value();
    absent_somewhere |= !p.lower.has_value() && !p.upper.has_value();
  }
  v1::ComponentPrior out;
  const int kinds = int{any_lower} + int{any_upper} + int{any_both};
  if (kinds == 0) {
    out.set_kind(v1::PRIOR_KIND_UNSPECIFIED);
  } else if (kinds > 1 || absent_somewhere || any_both) {
    out.set_kind(v1::PRIOR_KIND_BOX);
  } else {
    out.set_kind(any_lower ? v1::PRIOR_KIND_AT_LEAST : v1::PRIOR_KIND_AT_MOST);
  }
  for (const StepPrior& p : steps) {
    out.add_weight(p.weight > 0.0 ? p.weight : 0.0);
    out.add_target(p.weight > 0.0 ? p.target : 0.0);
    out.add_lower(p.lower.value_or(-kInf));
    out.add_upper(p.upper.value_or(kInf));
  }
  const auto compress = [](google::protobuf::RepeatedField<double>* f) {
    for (int i = 1; i < f->size(); ++i) {
      if (!((*f)[i] == (*f)[0])) return;
    }
    f->Truncate(std::min(f->size(), 1));
  };
  for (auto* f : {out.mutable_weight(), out.mutable_target(), out.mutable_lower(), out.mutable_upper()}) compress(f);
  switch (out.kind()) {
    case v1::PRIOR_KIND_UNSPECIFIED:
      out.clear_lower();
      out.clear_upper();
      break;
    case v1::PRIOR_KIND_AT_LEAST:
      out.clear_upper();
      break;
    case v1::PRIOR_KIND_AT_MOST:
      out.clear_lower();
      break;
    default:
      break;
  }
  if (out.kind() != v1::PRIOR_KIND_UNSPECIFIED) out.add_slope(kInf);  // hard bounds
  return out;
}

absl::Status ReadInstance(const Struct& doc, ProblemFile* out) {
  if (const Value* name = Member(doc, "name"); name != nullptr) out->name = name->string_value();
  if (const Value* family = Member(doc, "family"); family != nullptr) out->family = family->string_value();
  absl::StatusOr<const Value*> dims_value = Required(doc, "dims");
  if (!dims_value.ok()) return dims_value.status();
  if ((*dims_value)->kind_case() != Value::kStructValue) return Malformed("dims", "expected an object");
  const Struct& dims = (*dims_value)->struct_value();
  absl::StatusOr<int> M = Count(dims, "M", "dims.M"), L = Count(dims, "L", "dims.L");
  absl::StatusOr<int> K = Count(dims, "K", "dims.K"), N = Count(dims, "N", "dims.N");
  for (const auto* d : {&M, &L, &K, &N}) {
    if (!d->ok()) return d->status();
  }
  v1::ProblemSpec& spec = out->spec;
  v1::Model* model = spec.mutable_model();
  model->set_num_states(static_cast<unsigned>(*M));
  model->set_num_inputs(static_cast<unsigned>(*L));
  model->set_num_outputs(static_cast<unsigned>(*K));
  model->set_horizon(static_cast<unsigned>(*N));
  for (const char* name : {"A", "B", "C"}) {
    if (std::string(name) == "C" && *K == 0) continue;
    absl::StatusOr<const Value*> m = Required(doc, name);
    if (!m.ok()) return m.status();
    v1::Matrix* target = name[0] == 'A' ? model->add_a() : name[0] == 'B' ? model->add_b() : model->add_c();
    if (absl::Status s = ReadMatrix(**m, name, target); !s.ok()) return s;
  }

  v1::InitialState* x0 = spec.mutable_initial_state();
  if (const Value* x1 = Member(doc, "x1"); x1 != nullptr) {
    if (absl::Status s = Numbers(*x1, "x1", x0->mutable_mean()); !s.ok()) return s;
  } else {
    absl::StatusOr<const Value*> prior = Required(doc, "x1_prior");
    if (!prior.ok()) return Malformed("x1", "one of x1 and x1_prior is required");
    if ((*prior)->kind_case() != Value::kStructValue) return Malformed("x1_prior", "expected an object");
    absl::StatusOr<const Value*> mean = Required((*prior)->struct_value(), "mean");
    absl::StatusOr<const Value*> cov = Required((*prior)->struct_value(), "cov");
    if (!mean.ok() || !cov.ok()) return Malformed("x1_prior", "needs mean and cov");
    if (absl::Status s = Numbers(**mean, "x1_prior.mean", x0->mutable_mean()); !s.ok()) return s;
    if (absl::Status s = ReadMatrix(**cov, "x1_prior.cov", x0->mutable_covariance()); !s.ok()) return s;
  }

  // Quadratic parts: R and Qy diagonal, u_ref the same at every step, y_ref per step.
  std::vector<double> input_weight(static_cast<std::size_t>(*L), 0.0), u_ref(static_cast<std::size_t>(*L), 0.0);
  std::vector<double> output_weight(static_cast<std::size_t>(*K), 0.0);
  if (const Value* R = Member(doc, "R"); R != nullptr) {
    absl::StatusOr<std::vector<double>> d = Diagonal(*R, "R", *L);
    if (!d.ok()) return d.status();
    input_weight = *std::move(d);
  }
  if (const Value* ref = Member(doc, "u_ref"); ref != nullptr) {
    google::protobuf::RepeatedField<double> values;
    if (absl::Status s = Numbers(*ref, "u_ref", &values); !s.ok()) return s;
    if (values.size() != *L) return Malformed("u_ref", absl::StrCat("expected ", *L, " values"));
    u_ref.assign(values.begin(), values.end());
  }
  if (const Value* Qy = Member(doc, "Qy"); Qy != nullptr) {
    absl::StatusOr<std::vector<double>> d = Diagonal(*Qy, "Qy", *K);
    if (!d.ok()) return d.status();
    output_weight = *std::move(d);
  }
  absl::StatusOr<BoundTable> y_ref = BoundTable::Read(doc, "y_ref", *N, *K);
  absl::StatusOr<BoundTable> u_min = BoundTable::Read(doc, "u_min", *N, *L);
  absl::StatusOr<BoundTable> u_max = BoundTable::Read(doc, "u_max", *N, *L);
  absl::StatusOr<BoundTable> y_min = BoundTable::Read(doc, "y_min", *N, *K);
  absl::StatusOr<BoundTable> y_max = BoundTable::Read(doc, "y_max", *N, *K);
  for (const auto* t : {&y_ref, &u_min, &u_max, &y_min, &y_max}) {
    if (!t->ok()) return t->status();
  }

  // Inputs u[n] = u_{n+1}, n = 0..N-1; outputs y[n] = y_{n+1}, n = 0..N-1, none at n = N.
  for (int l = 0; l < *L; ++l) {
    std::vector<StepPrior> steps(static_cast<std::size_t>(*N));
    for (int n = 0; n < *N; ++n) {
      steps[n] = {u_min->at(n, l), u_max->at(n, l), input_weight[l], u_ref[l]};
    }
    *spec.add_input_priors() = Component(steps);
  }
  for (int k = 0; k < *K; ++k) {
    std::vector<StepPrior> steps(static_cast<std::size_t>(*N) + 1);
    for (int n = 0; n < *N; ++n) {
      steps[n] = {y_min->at(n, k), y_max->at(n, k), output_weight[k], y_ref->at(n, k).value_or(0.0)};
    }
    *spec.add_output_priors() = Component(steps);
  }

  if (const Value* Qf = Member(doc, "Qf"); Qf != nullptr) {
    v1::TerminalCost* terminal = spec.mutable_terminal();
    if (const Value* x_f = Member(doc, "x_f"); x_f != nullptr) {
      if (absl::Status s = Numbers(*x_f, "x_f", terminal->mutable_target()); !s.ok()) return s;
    } else {
      terminal->mutable_target()->Resize(*M, 0.0);
    }
    if (absl::Status s = ReadMatrix(*Qf, "Qf", terminal->mutable_weight()); !s.ok()) return s;
  }

  if (const Value* closed_loop = Member(doc, "closed_loop"); closed_loop != nullptr) {
    if (closed_loop->kind_case() != Value::kStructValue) return Malformed("closed_loop", "expected an object");
    absl::StatusOr<const Value*> x1 = Required(closed_loop->struct_value(), "x1");
    if (!x1.ok()) return Malformed("closed_loop.x1", "required");
    absl::StatusOr<const ListValue*> states = List(**x1, "closed_loop.x1");
    if (!states.ok()) return states.status();
    for (int t = 0; t < (*states)->values_size(); ++t) {
      google::protobuf::RepeatedField<double> x;
      if (absl::Status s = Numbers((*states)->values(t), absl::StrCat("closed_loop.x1[", t, "]"), &x); !s.ok()) {
        return s;
      }
      out->closed_loop_states.emplace_back(x.begin(), x.end());
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::string> ReadTextFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

namespace {

absl::StatusOr<ProblemFile> InstanceFromText(const std::string& path, const std::string& text) {
  Struct doc;
  if (const auto status = google::protobuf::util::JsonStringToMessage(text, &doc); !status.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not JSON: ", status.ToString()));
  }
  ProblemFile out;
  if (absl::Status s = ReadInstance(doc, &out); !s.ok()) {
    return absl::Status(s.code(), absl::StrCat(path, ": malformed instance: ", s.message()));
  }
  return out;
}

}  // namespace

absl::StatusOr<ProblemFile> LoadBenchmarkInstanceSpec(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return InstanceFromText(path, *text);
}

absl::StatusOr<ProblemFile> LoadProblemFile(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return ParseProblemFile(path, *text);
}

absl::StatusOr<ProblemFile> ParseProblemFile(const std::string& name, const std::string& text) {
  if (text.find("\"dims\"") != std::string::npos) return InstanceFromText(name, text);  // the benchmark format
  ProblemFile out;
  const auto status = google::protobuf::util::JsonStringToMessage(text, &out.spec);
  if (!status.ok()) return absl::InvalidArgumentError(absl::StrCat(name, ": not a ProblemSpec: ", status.ToString()));
  return out;
}

}  // namespace nupmpc
