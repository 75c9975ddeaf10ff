#include "core/model/multilevel_inputs.h"

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

int Columns(const InputLevels& levels) { return levels.count == 0 ? 1 : levels.count - 1; }

}  // namespace

absl::StatusOr<Problem> ExpandMultiLevelInputs(const Problem& p, const std::vector<InputLevels>& levels, bool em) {
  NUPMPC_RETURN_IF_ERROR(Validate(p));
  const int L = p.num_inputs, N = p.horizon, M = p.num_states;
  if (levels.size() != static_cast<std::size_t>(L)) {
    return absl::InvalidArgumentError(
        absl::StrCat("levels: expected one entry per input (", L, "), got ", levels.size()));
  }
  int expanded_L = 0;
  for (int l = 0; l < L; ++l) {
    const InputLevels& v = levels[l];
    const std::string field = absl::StrCat("levels[", l, "]");
    if (v.count != 0 && v.count < 2)
      return absl::InvalidArgumentError(absl::StrCat(field, ".count: must be 0 or >= 2"));
    if (v.count != 0 && !(v.spacing > 0.0 && std::isfinite(v.spacing) && std::isfinite(v.lowest))) {
      return absl::InvalidArgumentError(absl::StrCat(field, ": lowest must be finite and spacing finite and > 0"));
    }
    if (v.count != 0) {
      for (int n = 0; n < N; ++n) {
        const ScalarPrior& prior = p.input_prior(n, l);
        if (prior.kind != PriorKind::kNone || prior.has_gaussian()) {
          return absl::InvalidArgumentError(absl::StrCat("input_priors[", n * L + l, "]: input ", l,
                                                         " is multi-level, so it takes no prior of its own"));
        }
      }
    }
    expanded_L += Columns(v);
  }

  Problem e = p;
  e.num_inputs = expanded_L;
  const int model_steps = static_cast<int>(p.B.size());
  e.B.clear();
  for (int n = 0; n < model_steps; ++n) {
    const Eigen::MatrixXd& B = p.B[n];
    Eigen::MatrixXd expanded(M, expanded_L);
    int column = 0;
    for (int l = 0; l < L; ++l) {
      const int columns = Columns(levels[l]);
      for (int j = 0; j < columns; ++j) {
        expanded.col(column++) = levels[l].count == 0 ? B.col(l) : Eigen::VectorXd(levels[l].spacing * B.col(l));
      }
    }
    e.B.push_back(std::move(expanded));
  }
  // β0 b of every multi-level input joins the state offset (per step if B varies).
  bool any_offset = false;
  for (const InputLevels& v : levels) any_offset |= v.count != 0 && v.lowest != 0.0;
  if (any_offset) {
    const int offset_steps = std::max<int>({1, model_steps == 1 ? 1 : N, static_cast<int>(p.state_offset.size())});
    e.state_offset.assign(offset_steps, Eigen::VectorXd::Zero(M));
    for (int n = 0; n < offset_steps; ++n) {
      if (!p.state_offset.empty())
        e.state_offset[n] = p.state_offset.size() == 1 ? p.state_offset[0] : p.state_offset[n];
      const Eigen::MatrixXd& B = p.B_at(n);
      for (int l = 0; l < L; ++l) {
        if (levels[l].count != 0) e.state_offset[n] += levels[l].lowest * B.col(l);
      }
    }
  }
  e.input_priors.assign(static_cast<std::size_t>(N) * expanded_L, ScalarPrior::Free());
  for (int n = 0; n < N; ++n) {
    int column = 0;
    for (int l = 0; l < L; ++l) {
      const int columns = Columns(levels[l]);
      for (int j = 0; j < columns; ++j, ++column) {
        ScalarPrior& prior = e.input_priors[static_cast<std::size_t>(n) * expanded_L + column];
        if (levels[l].count == 0) {
          prior = p.input_prior(n, l);
        } else {
          prior = ScalarPrior::Binary(0.0, 1.0, em);
          prior.initial_variance = 1.0 + 0.01 * j;  // symmetry breaking ([KL] eq. 80)
          prior.rounds_with_next = j + 1 < columns;
        }
      }
    }
  }
  return e;
}

Eigen::MatrixXd InputsFromLevels(const Eigen::MatrixXd& expanded, const std::vector<InputLevels>& levels) {
  Eigen::MatrixXd u(expanded.rows(), static_cast<Eigen::Index>(levels.size()));
  int column = 0;
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const int columns = Columns(levels[l]);
    if (levels[l].count == 0) {
      u.col(l) = expanded.col(column);
    } else {
      u.col(l) = (levels[l].lowest + levels[l].spacing * expanded.middleCols(column, columns).rowwise().sum().array())
                     .matrix();
    }
    column += columns;
  }
  return u;
}

}  // namespace nupmpc::core
