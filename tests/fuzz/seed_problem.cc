#include "tests/fuzz/seed_problem.h"

#include <cmath>

namespace nupmpc::fuzz {
namespace {

constexpr int kM = 4, kL = 1, kK = 4, kN = 10;

void Fill(v1::Matrix* m, int rows, int cols, std::initializer_list<double> data) {
  m->set_rows(rows);
  m->set_cols(cols);
  m->mutable_data()->Add(data.begin(), data.end());
}

}  // namespace

v1::ProblemSpec SeedSpec() {
  v1::ProblemSpec s;
  v1::Model* m = s.mutable_model();
  m->set_num_states(kM);
  m->set_num_inputs(kL);
  m->set_num_outputs(kK);
  m->set_horizon(kN);
  // Positions p1, p2 and velocities v1, v2; springs to the walls and between the masses,
  // explicit Euler with step 0.1; the input pushes the masses apart.
  Fill(m->add_a(), kM, kM, {1, 0, 0.1, 0, 0, 1, 0, 0.1, -0.2, 0.1, 1, 0, 0.1, -0.2, 0, 1});
  Fill(m->add_b(), kM, kL, {0, 0, -0.1, 0.1});
  Fill(m->add_c(), kK, kM, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1});
  s.mutable_initial_state()->mutable_mean()->Resize(kM, 0.0);
  v1::ComponentPrior* u = s.add_input_priors();
  u->set_kind(v1::PRIOR_KIND_BOX);
  u->add_weight(1.0);
  u->add_lower(-0.5);
  u->add_upper(0.5);
  for (int k = 0; k < kK; ++k) {
    v1::ComponentPrior* y = s.add_output_priors();
    y->set_kind(v1::PRIOR_KIND_BOX);
    y->add_weight(1.0);
    y->add_lower(-4.0);
    y->add_upper(4.0);
  }
  s.mutable_terminal()->mutable_target()->Resize(kM, 0.0);
  Fill(s.mutable_terminal()->mutable_weight(), kM, kM, {5, 0, 0, 0, 0, 5, 0, 0, 0, 0, 5, 0, 0, 0, 0, 5});
  return s;
}

v1::Step SeedStep(int k) {
  v1::Step step;
  for (int i = 0; i < kM; ++i) step.add_state(std::sin(1.0 + 0.7 * k + 1.3 * i));
  return step;
}

}  // namespace nupmpc::fuzz
