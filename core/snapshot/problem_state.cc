#include "core/snapshot/problem_state.h"

#include <algorithm>
#include <array>
#include <vector>

namespace nupmpc::core {
namespace {

// A model term of `count` matrices of rows × cols each, where `count` is one of `allowed`
// (e.g. 1 or N): the count first, then each matrix with its fixed shape.
template <class Matrix>
void PersistTerm(StateArchive& archive, const char* name, std::vector<Matrix>& term, std::array<int, 3> allowed,
                 int rows, int cols) {
  int count = static_cast<int>(term.size());
  archive.Integer(name, count, 0, *std::max_element(allowed.begin(), allowed.end()));
  if (!archive.ok()) return;
  if (archive.restoring() && count != static_cast<int>(term.size())) {
    if (std::find(allowed.begin(), allowed.end(), count) == allowed.end()) {
      return archive.Fail(name, "number of matrices is not one this term allows");
    }
    // Only what the input's length pays for is allocated.
    const std::size_t bytes = static_cast<std::size_t>(count) * rows * cols * sizeof(double);
    if (!archive.Reserve(name, bytes)) return;
    term.resize(count);
    for (Matrix& m : term) m.setZero(rows, cols);
  }
  for (Matrix& m : term) archive.Field(name, m);
}

// The priors as columns (each ScalarPrior field an array), the kinds range-checked.
void PersistPriors(StateArchive& archive, const char* name, std::vector<ScalarPrior>& priors) {
  archive.BeginSection(name);
  const std::size_t n = priors.size();
  std::vector<double> values(8 * n);
  std::vector<PriorKind> kinds(n);
  std::vector<int> flags(n);
  for (std::size_t i = 0; i < n; ++i) {
    const ScalarPrior& p = priors[i];
    const double row[8] = {p.mean, p.variance, p.lower, p.upper, p.slope, p.radius, p.exponent, p.initial_variance};
    std::copy(row, row + 8, values.begin() + static_cast<std::ptrdiff_t>(8 * i));
    kinds[i] = p.kind;
    flags[i] = (p.em ? 1 : 0) | (p.rounds_with_next ? 2 : 0);
  }
  archive.Field("values", values);
  archive.EnumeratorField("kind", kinds, PriorKind::kNone, PriorKind::kBinary);
  archive.Field("flags", flags);
  if (archive.restoring() && archive.ok()) {
    for (std::size_t i = 0; i < n; ++i) {
      if (flags[i] < 0 || flags[i] > 3) return archive.Fail("flags", "unknown flag bits");
      ScalarPrior& p = priors[i];
      const double* row = values.data() + 8 * i;
      p.mean = row[0];
      p.variance = row[1];
      p.lower = row[2];
      p.upper = row[3];
      p.slope = row[4];
      p.radius = row[5];
      p.exponent = row[6];
      p.initial_variance = row[7];
      p.kind = kinds[i];
      p.em = (flags[i] & 1) != 0;
      p.rounds_with_next = (flags[i] & 2) != 0;
    }
  }
  archive.EndSection();
}

}  // namespace

void PersistProblemValues(StateArchive& archive, Problem& p) {
  const int M = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  archive.BeginSection("problem");
  archive.Field("initial_mean", p.initial_mean);
  archive.Field("initial_covariance", p.initial_covariance);
  PersistTerm(archive, "A", p.A, {1, N, 1}, M, M);
  PersistTerm(archive, "B", p.B, {1, N, 1}, M, L);
  PersistTerm(archive, "C", p.C, {1, N + 1, 1}, K, M);
  PersistTerm(archive, "state_offset", p.state_offset, {0, 1, N}, M, 1);
  PersistTerm(archive, "output_offset", p.output_offset, {0, 1, N + 1}, K, 1);
  PersistPriors(archive, "input_priors", p.input_priors);
  PersistPriors(archive, "output_priors", p.output_priors);
  // The terminal cost's presence is part of the shape (the creation spec's).
  if (p.terminal.has_value()) {
    archive.Field("terminal_target", p.terminal->target);
    archive.Field("terminal_weight", p.terminal->weight);
  }
  archive.EndSection();
}

}  // namespace nupmpc::core
