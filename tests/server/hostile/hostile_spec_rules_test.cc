// The hostile-input catalogue's rule class: every validation rule of a spec
// (dimensions and limits, each matrix, per-step array, enum, bound relation, prior
// parameter, option, multi-level inputs, input differences, keep-out regions, the GP
// model), of a step and of a FitGpModel request, broken one at a time. Each case gets its
// code and a message naming the field or the rule, from SolveOnce and CreateSession alike
// (a refused step leaves its session as it was); after each one a healthy session still
// answers with the bit-identical plan and the server's resident memory has not jumped.
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "tests/server/hostile/hostile_catalogue.h"

namespace nupmpc::testing {
namespace {

using C = absl::StatusCode;
constexpr double kInf = std::numeric_limits<double>::infinity();

// A rule broken in a valid spec: masses_N30 (12 states, 3 inputs with box priors, 12
// outputs with box priors, N = 30, a terminal cost) unless `gp`, then GpSpec().
struct SpecRule {
  const char* rule;
  std::function<void(v1::ProblemSpec*)> mutate;
  C code;
  const char* field;  // must appear in the message
  bool gp = false;
};

// Replaces `c` by a prior of `kind` with weight 1 (and nothing else).
v1::ComponentPrior* Fresh(v1::ComponentPrior* c, v1::PriorKind kind) {
  c->Clear();
  c->set_kind(kind);
  c->add_weight(1.0);
  return c;
}

void SetMatrix(v1::Matrix* m, int rows, int cols, std::vector<double> data) {
  m->set_rows(rows);
  m->set_cols(cols);
  m->mutable_data()->Assign(data.begin(), data.end());
}

// A GP session's spec on four given training pairs (kernel given, so no fit): y[k] from
// y[k-1] and u[k-1], horizon 5.
v1::ProblemSpec GpSpec() {
  v1::ProblemSpec spec;
  v1::GpMpc* g = spec.mutable_gp();
  v1::GpModel* m = g->mutable_model();
  m->set_output_lags(1);
  m->set_input_lags(0);
  SetMatrix(m->mutable_regressors(), 4, 2, {0, 0, 1, 0, 0, 1, 1, 1});
  for (double t : {0.0, 0.5, 0.2, 0.7}) m->add_targets(t);
  m->mutable_kernel()->set_signal_variance(1.0);
  m->mutable_kernel()->set_noise_variance(0.01);
  m->mutable_kernel()->add_length_scales(1.0);
  m->mutable_kernel()->add_length_scales(1.0);
  g->set_horizon(5);
  g->set_output_weight(1.0);
  g->set_input_change_weight(0.1);
  g->set_input_min(-1.0);
  g->set_input_max(1.0);
  g->set_rate_min(-0.5);
  g->set_rate_max(0.5);
  g->set_output_min(-10.0);
  g->set_output_max(10.0);
  g->set_sigma_multiple(2.0);
  return spec;
}

// Input 0 as a three-level input (its own prior cleared, as the rule wants).
void ThreeLevelInput(v1::ProblemSpec* s) {
  s->mutable_input_priors(0)->Clear();
  v1::InputLevels* levels = s->add_input_levels();
  levels->set_input(0);
  levels->set_count(3);
  levels->set_lowest(-1.0);
  levels->set_spacing(1.0);
}

void InputDifferences(v1::ProblemSpec* s) {
  for (int l = 0; l < 3; ++l) s->mutable_input_differences()->add_priors()->add_weight(1.0);
}

v1::KeepOutRegion* KeepOut(v1::ProblemSpec* s) {
  v1::KeepOut* k = s->mutable_keep_out();
  k->set_first_output(0);
  k->set_second_output(1);
  v1::KeepOutRegion* r = k->add_regions();
  r->set_shape(v1::KeepOutRegion::SHAPE_ELLIPSE);
  r->set_centre_x(100.0);
  r->set_centre_y(100.0);
  r->set_half_axis_a(1.0);
  return r;
}

std::vector<SpecRule> ModelRules() {
  return {
      {"no model", [](v1::ProblemSpec* s) { s->clear_model(); }, C::kInvalidArgument, "spec.model"},
      {"zero states", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_states(0); }, C::kInvalidArgument,
       "spec.model.num_states"},
      {"zero inputs", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_inputs(0); }, C::kInvalidArgument,
       "spec.model.num_inputs"},
      {"zero horizon", [](v1::ProblemSpec* s) { s->mutable_model()->set_horizon(0); }, C::kInvalidArgument,
       "spec.model.horizon"},
      {"states over --max_states", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_states(1001); },
       C::kResourceExhausted, "spec.model.num_states"},
      {"inputs over the limit", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_inputs(1001); },
       C::kResourceExhausted, "spec.model.num_inputs"},
      {"outputs over the limit", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_outputs(1001); },
       C::kResourceExhausted, "spec.model.num_outputs"},
      {"horizon over --max_horizon", [](v1::ProblemSpec* s) { s->mutable_model()->set_horizon(100001); },
       C::kResourceExhausted, "spec.model.horizon"},
      {"session over --max_session_memory_mb",
       [](v1::ProblemSpec* s) {
         s->mutable_model()->set_num_states(1000);
         s->mutable_model()->set_horizon(100000);
       },
       C::kResourceExhausted, "max_session_bytes"},
      {"two A matrices for thirty steps", [](v1::ProblemSpec* s) { *s->mutable_model()->add_a() = s->model().a(0); },
       C::kInvalidArgument, "spec.model.a"},
      {"A of wrong shape", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_a(0)->set_rows(11); },
       C::kInvalidArgument, "spec.model.a[0]"},
      {"A data short", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_a(0)->mutable_data()->RemoveLast(); },
       C::kInvalidArgument, "spec.model.a[0].data"},
      {"per-step A, one of wrong shape",
       [](v1::ProblemSpec* s) {
         const v1::Matrix a = s->model().a(0);
         for (int n = 1; n < 30; ++n) *s->mutable_model()->add_a() = a;
         s->mutable_model()->mutable_a(17)->set_cols(3);
       },
       C::kInvalidArgument, "spec.model.a[17]"},
      {"B of wrong shape", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_b(0)->set_cols(2); },
       C::kInvalidArgument, "spec.model.b[0]"},
      {"B data long", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_b(0)->add_data(1.0); }, C::kInvalidArgument,
       "spec.model.b[0].data"},
      {"no B", [](v1::ProblemSpec* s) { s->mutable_model()->clear_b(); }, C::kInvalidArgument, "spec.model.b"},
      {"two C matrices", [](v1::ProblemSpec* s) { *s->mutable_model()->add_c() = s->model().c(0); },
       C::kInvalidArgument, "spec.model.c"},
      {"C of wrong shape", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_c(0)->set_rows(6); },
       C::kInvalidArgument, "spec.model.c[0]"},
      {"C data short", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_c(0)->mutable_data()->RemoveLast(); },
       C::kInvalidArgument, "spec.model.c[0].data"},
      {"state offset of wrong length", [](v1::ProblemSpec* s) { s->mutable_model()->add_state_offset(1.0); },
       C::kInvalidArgument, "spec.model.state_offset"},
      {"output offset of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 13; ++i) s->mutable_model()->add_output_offset(0.0);
       },
       C::kInvalidArgument, "spec.model.output_offset"},
      {"initial mean of wrong length",
       [](v1::ProblemSpec* s) { s->mutable_initial_state()->mutable_mean()->RemoveLast(); }, C::kInvalidArgument,
       "spec.initial_state.mean"},
      {"covariance of wrong shape",
       [](v1::ProblemSpec* s) {
         SetMatrix(s->mutable_initial_state()->mutable_covariance(), 2, 2, {1, 0, 0, 1});
       },
       C::kInvalidArgument, "spec.initial_state.covariance"},
      {"covariance not symmetric",
       [](v1::ProblemSpec* s) {
         std::vector<double> v(144, 0.0);
         for (int i = 0; i < 12; ++i) v[i * 13] = 1.0;
         v[1] = 0.5;
         SetMatrix(s->mutable_initial_state()->mutable_covariance(), 12, 12, v);
       },
       C::kInvalidArgument, "spec.initial_state.covariance"},
      {"covariance not positive definite",
       [](v1::ProblemSpec* s) {
         std::vector<double> v(144, 0.0);
         for (int i = 0; i < 12; ++i) v[i * 13] = i == 5 ? -1.0 : 1.0;
         SetMatrix(s->mutable_initial_state()->mutable_covariance(), 12, 12, v);
       },
       C::kInvalidArgument, "spec.initial_state.covariance"},
      {"terminal target of wrong length", [](v1::ProblemSpec* s) { s->mutable_terminal()->add_target(0.0); },
       C::kInvalidArgument, "spec.terminal.target"},
      {"terminal weight of wrong shape",
       [](v1::ProblemSpec* s) { s->mutable_terminal()->mutable_weight()->set_cols(4); }, C::kInvalidArgument,
       "spec.terminal.weight"},
      {"terminal weight not symmetric",
       [](v1::ProblemSpec* s) { s->mutable_terminal()->mutable_weight()->set_data(1, 123.0); }, C::kInvalidArgument,
       "spec.terminal.weight"},
      {"terminal weight not positive semidefinite",
       [](v1::ProblemSpec* s) {
         std::vector<double> v(144, 0.0);
         for (int i = 0; i < 12; ++i) v[i * 13] = i == 0 ? -5.0 : 1.0;
         SetMatrix(s->mutable_terminal()->mutable_weight(), 12, 12, v);
       },
       C::kInvalidArgument, "spec.terminal.weight"},
  };
}

std::vector<SpecRule> PriorRules() {
  return {
      {"input priors fewer than inputs", [](v1::ProblemSpec* s) { s->mutable_input_priors()->RemoveLast(); },
       C::kInvalidArgument, "spec.input_priors"},
      {"output priors more than outputs", [](v1::ProblemSpec* s) { s->add_output_priors(); }, C::kInvalidArgument,
       "spec.output_priors"},
      {"weight array of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 4; ++i) s->mutable_input_priors(0)->add_weight(1.0);
       },
       C::kInvalidArgument, "spec.input_priors[0].weight"},
      {"target array of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 2; ++i) s->mutable_output_priors(1)->add_target(0.0);
       },
       C::kInvalidArgument, "spec.output_priors[1].target"},
      {"lower array of wrong length (outputs: N + 1 steps)",
       [](v1::ProblemSpec* s) {
         auto* c = s->mutable_output_priors(0);
         c->clear_lower();
         for (int i = 0; i < 30; ++i) c->add_lower(-1.0);
       },
       C::kInvalidArgument, "spec.output_priors[0].lower"},
      {"upper array of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 5; ++i) s->mutable_input_priors(2)->add_upper(1.0);
       },
       C::kInvalidArgument, "spec.input_priors[2].upper"},
      {"slope array of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 3; ++i) s->mutable_input_priors(1)->add_slope(1.0);
       },
       C::kInvalidArgument, "spec.input_priors[1].slope"},
      {"radius array of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 3; ++i) s->mutable_input_priors(1)->add_radius(1.0);
       },
       C::kInvalidArgument, "spec.input_priors[1].radius"},
      {"exponent array of wrong length",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 3; ++i) s->mutable_input_priors(1)->add_exponent(0.5);
       },
       C::kInvalidArgument, "spec.input_priors[1].exponent"},
      {"unknown prior kind",
       [](v1::ProblemSpec* s) { s->mutable_input_priors(0)->set_kind(static_cast<v1::PriorKind>(42)); },
       C::kInvalidArgument, "spec.input_priors[0].kind"},
      {"unknown estimation",
       [](v1::ProblemSpec* s) { s->mutable_output_priors(3)->set_estimation(static_cast<v1::Estimation>(9)); },
       C::kInvalidArgument, "spec.output_priors[3].estimation"},
      {"negative weight", [](v1::ProblemSpec* s) { s->mutable_input_priors(0)->set_weight(0, -1.0); },
       C::kInvalidArgument, "spec.input_priors[0].weight"},
      {"zero slope", [](v1::ProblemSpec* s) { s->mutable_input_priors(1)->add_slope(0.0); }, C::kInvalidArgument,
       "spec.input_priors[1].slope"},
      {"BOX without bounds", [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(0), v1::PRIOR_KIND_BOX); },
       C::kInvalidArgument, "spec.input_priors[0]: BOX needs"},
      {"BOX with lower above upper",
       [](v1::ProblemSpec* s) {
         s->mutable_input_priors(0)->set_lower(0, 1.0);
         s->mutable_input_priors(0)->set_upper(0, -1.0);
       },
       C::kInvalidArgument, "spec.input_priors[0] at step 0: lower"},
      {"BOX with lower equal to upper",
       [](v1::ProblemSpec* s) {
         s->mutable_output_priors(2)->set_lower(0, 0.25);
         s->mutable_output_priors(2)->set_upper(0, 0.25);
       },
       C::kInvalidArgument, "spec.output_priors[2] at step 0: lower"},
      {"BOX with lower +Infinity", [](v1::ProblemSpec* s) { s->mutable_input_priors(1)->set_lower(0, kInf); },
       C::kInvalidArgument, "spec.input_priors[1] at step 0: bounds"},
      {"AT_LEAST without lower",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(0), v1::PRIOR_KIND_AT_LEAST)->add_upper(1.0); },
       C::kInvalidArgument, "spec.input_priors[0].lower"},
      {"AT_MOST without upper",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(0), v1::PRIOR_KIND_AT_MOST)->add_lower(1.0); },
       C::kInvalidArgument, "spec.input_priors[0].upper"},
      {"AT_MOST at -Infinity",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(2), v1::PRIOR_KIND_AT_MOST)->add_upper(-kInf); },
       C::kInvalidArgument, "spec.input_priors[2] at step 0: bounds"},
      {"L1 without slope", [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(0), v1::PRIOR_KIND_L1); },
       C::kInvalidArgument, "spec.input_priors[0].slope"},
      {"L1 with an infinite centre",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(0), v1::PRIOR_KIND_L1);
         c->add_slope(1.0);
         c->add_lower(-kInf);
       },
       C::kInvalidArgument, "spec.input_priors[0].lower"},
      {"L1 with an infinite slope",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(0), v1::PRIOR_KIND_L1)->add_slope(kInf); },
       C::kInvalidArgument, "spec.input_priors[0].slope"},
      {"HUBER without slope", [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(1), v1::PRIOR_KIND_HUBER); },
       C::kInvalidArgument, "spec.input_priors[1].slope"},
      {"HUBER with zero radius",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(1), v1::PRIOR_KIND_HUBER);
         c->add_slope(1.0);
         c->add_radius(0.0);
       },
       C::kInvalidArgument, "spec.input_priors[1].radius"},
      {"PLAIN_NUV with an infinite centre",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_output_priors(4), v1::PRIOR_KIND_PLAIN_NUV)->add_lower(kInf); },
       C::kInvalidArgument, "spec.output_priors[4].lower"},
      {"SMOOTHED_NUV with a negative radius",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_output_priors(4), v1::PRIOR_KIND_SMOOTHED_NUV)->add_radius(-1.0); },
       C::kInvalidArgument, "spec.output_priors[4].radius"},
      {"LP without slope",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(2), v1::PRIOR_KIND_LP)->add_exponent(0.5); },
       C::kInvalidArgument, "spec.input_priors[2].slope"},
      {"LP exponent above one",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(2), v1::PRIOR_KIND_LP);
         c->add_slope(1.0);
         c->add_exponent(1.5);
       },
       C::kInvalidArgument, "spec.input_priors[2].exponent"},
      {"LP exponent zero",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(2), v1::PRIOR_KIND_LP);
         c->add_slope(1.0);
         c->add_exponent(0.0);
       },
       C::kInvalidArgument, "spec.input_priors[2].exponent"},
      {"LP with an infinite slope",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(2), v1::PRIOR_KIND_LP);
         c->add_slope(kInf);
         c->add_exponent(0.5);
       },
       C::kInvalidArgument, "spec.input_priors[2].slope"},
      {"BINARY with one level",
       [](v1::ProblemSpec* s) { Fresh(s->mutable_input_priors(1), v1::PRIOR_KIND_BINARY)->add_lower(0.0); },
       C::kInvalidArgument, "spec.input_priors[1]: BINARY needs both levels"},
      {"BINARY with levels in the wrong order",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(1), v1::PRIOR_KIND_BINARY);
         c->add_lower(1.0);
         c->add_upper(0.0);
       },
       C::kInvalidArgument, "spec.input_priors[1] at step 0: levels"},
      {"BINARY with an infinite level",
       [](v1::ProblemSpec* s) {
         auto* c = Fresh(s->mutable_input_priors(1), v1::PRIOR_KIND_BINARY);
         c->add_lower(0.0);
         c->add_upper(kInf);
       },
       C::kInvalidArgument, "spec.input_priors[1] at step 0: levels"},
  };
}

std::vector<SpecRule> OptionRules() {
  return {
      {"unknown algorithm",
       [](v1::ProblemSpec* s) { s->mutable_options()->set_algorithm(static_cast<v1::Algorithm>(99)); },
       C::kInvalidArgument, "spec.options.algorithm"},
      {"iteration cap over --max_iterations",
       [](v1::ProblemSpec* s) { s->mutable_options()->set_max_iterations(100001); }, C::kResourceExhausted,
       "spec.options.max_iterations"},
      {"negative objective tolerance", [](v1::ProblemSpec* s) { s->mutable_options()->set_objective_tolerance(-1e-9); },
       C::kInvalidArgument, "spec.options.objective_tolerance"},
      {"negative violation tolerance", [](v1::ProblemSpec* s) { s->mutable_options()->set_violation_tolerance(-1.0); },
       C::kInvalidArgument, "spec.options.violation_tolerance"},
      {"negative time limit", [](v1::ProblemSpec* s) { s->mutable_options()->set_time_limit_ms(-5.0); },
       C::kInvalidArgument, "spec.options.time_limit_ms"},
      {"negative elastic slope", [](v1::ProblemSpec* s) { s->mutable_options()->set_elastic_slope(-1.0); },
       C::kInvalidArgument, "spec.options.elastic_slope"},
      {"elastic after more iterations than the limit",
       [](v1::ProblemSpec* s) { s->mutable_options()->set_elastic_after_iterations(100001); }, C::kInvalidArgument,
       "spec.options.elastic_after_iterations"},
      {"forced algorithm that cannot handle output bounds",
       [](v1::ProblemSpec* s) { s->mutable_options()->set_algorithm(v1::ALGORITHM_IBFFD); }, C::kFailedPrecondition,
       "spec:"},
  };
}

std::vector<SpecRule> InputMapRules() {
  return {
      {"level entry of an input that does not exist",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         s->mutable_input_levels(0)->set_input(3);
       },
       C::kInvalidArgument, "spec.input_levels[0].input"},
      {"one input listed twice",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         *s->add_input_levels() = s->input_levels(0);
       },
       C::kInvalidArgument, "spec.input_levels[1].input"},
      {"one level",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         s->mutable_input_levels(0)->set_count(1);
       },
       C::kInvalidArgument, "spec.input_levels[0].count"},
      {"levels over the limit",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         s->mutable_input_levels(0)->set_count(65);
       },
       C::kResourceExhausted, "spec.input_levels[0].count"},
      {"infinite lowest level",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         s->mutable_input_levels(0)->set_lowest(-kInf);
       },
       C::kInvalidArgument, "spec.input_levels[0].lowest"},
      {"zero spacing",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         s->mutable_input_levels(0)->set_spacing(0.0);
       },
       C::kInvalidArgument, "spec.input_levels[0].spacing"},
      {"multi-level input with a prior of its own",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         s->mutable_input_priors(0)->add_weight(1.0);
       },
       C::kInvalidArgument, "spec.input_priors[0]"},
      {"levels and differences together",
       [](v1::ProblemSpec* s) {
         ThreeLevelInput(s);
         InputDifferences(s);
       },
       C::kInvalidArgument, "spec.input_differences"},
      {"difference priors fewer than inputs",
       [](v1::ProblemSpec* s) {
         InputDifferences(s);
         s->mutable_input_differences()->mutable_priors()->RemoveLast();
       },
       C::kInvalidArgument, "spec.input_differences.priors"},
      {"difference prior with lower above upper",
       [](v1::ProblemSpec* s) {
         InputDifferences(s);
         auto* c = Fresh(s->mutable_input_differences()->mutable_priors(1), v1::PRIOR_KIND_BOX);
         c->add_lower(1.0);
         c->add_upper(-1.0);
       },
       C::kInvalidArgument, "spec.input_differences.priors[1]"},
      {"previous input of wrong length",
       [](v1::ProblemSpec* s) {
         InputDifferences(s);
         s->mutable_input_differences()->add_previous_input(0.0);
       },
       C::kInvalidArgument, "spec.input_differences.previous_input"},
  };
}

std::vector<SpecRule> KeepOutRules() {
  return {
      {"first output out of range",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->set_first_output(12);
       },
       C::kInvalidArgument, "spec.keep_out.first_output"},
      {"second output out of range",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->set_second_output(40);
       },
       C::kInvalidArgument, "spec.keep_out.second_output"},
      {"the same output twice",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->set_second_output(0);
       },
       C::kInvalidArgument, "spec.keep_out.second_output"},
      {"no region",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->clear_regions();
       },
       C::kInvalidArgument, "spec.keep_out.regions"},
      {"regions over the limit",
       [](v1::ProblemSpec* s) {
         const v1::KeepOutRegion r = *KeepOut(s);
         for (int i = 0; i < 256; ++i) *s->mutable_keep_out()->add_regions() = r;
       },
       C::kResourceExhausted, "spec.keep_out.regions"},
      {"rectangle order out of range",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->set_rectangle_order(33);
       },
       C::kInvalidArgument, "spec.keep_out.rectangle_order"},
      {"unknown shape", [](v1::ProblemSpec* s) { KeepOut(s)->set_shape(static_cast<v1::KeepOutRegion::Shape>(7)); },
       C::kInvalidArgument, "spec.keep_out.regions[0].shape"},
      {"zero half axis", [](v1::ProblemSpec* s) { KeepOut(s)->set_half_axis_a(0.0); }, C::kInvalidArgument,
       "spec.keep_out.regions[0].half_axis_a"},
      {"negative second half axis", [](v1::ProblemSpec* s) { KeepOut(s)->set_half_axis_b(-1.0); }, C::kInvalidArgument,
       "spec.keep_out.regions[0].half_axis_b"},
      {"negative margin", [](v1::ProblemSpec* s) { KeepOut(s)->set_margin(-0.1); }, C::kInvalidArgument,
       "spec.keep_out.regions[0].margin"},
      {"negative slope", [](v1::ProblemSpec* s) { KeepOut(s)->set_slope(-1.0); }, C::kInvalidArgument,
       "spec.keep_out.regions[0].slope"},
      {"linearisations over the limit",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->set_max_linearisations(10001);
       },
       C::kInvalidArgument, "spec.keep_out.max_linearisations"},
      {"negative step tolerance",
       [](v1::ProblemSpec* s) {
         KeepOut(s);
         s->mutable_keep_out()->set_step_tolerance(-1.0);
       },
       C::kInvalidArgument, "spec.keep_out.step_tolerance"},
  };
}

std::vector<SpecRule> GpRules() {
  const auto gp = [](const char* rule, std::function<void(v1::ProblemSpec*)> mutate, C code, const char* field) {
    return SpecRule{rule, std::move(mutate), code, field, /*gp=*/true};
  };
  return {
      gp(
          "GP with a linear model too", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_states(1); },
          C::kInvalidArgument, "spec.model"),
      gp(
          "GP with input priors", [](v1::ProblemSpec* s) { s->add_input_priors(); }, C::kInvalidArgument,
          "spec.input_priors"),
      gp(
          "GP with output priors", [](v1::ProblemSpec* s) { s->add_output_priors(); }, C::kInvalidArgument,
          "spec.output_priors"),
      gp(
          "GP with a terminal cost", [](v1::ProblemSpec* s) { s->mutable_terminal(); }, C::kInvalidArgument,
          "spec.terminal"),
      gp(
          "GP with input levels", [](v1::ProblemSpec* s) { s->add_input_levels()->set_count(2); }, C::kInvalidArgument,
          "spec.input_levels"),
      gp(
          "GP with input differences", [](v1::ProblemSpec* s) { s->mutable_input_differences(); }, C::kInvalidArgument,
          "spec.input_differences"),
      gp(
          "GP with keep-out regions", [](v1::ProblemSpec* s) { s->mutable_keep_out()->add_regions(); },
          C::kInvalidArgument, "spec.keep_out"),
      gp(
          "GP with a linear solver option", [](v1::ProblemSpec* s) { s->mutable_options()->set_max_iterations(10); },
          C::kInvalidArgument, "spec.options"),
      gp(
          "GP without model", [](v1::ProblemSpec* s) { s->mutable_gp()->clear_model(); }, C::kInvalidArgument,
          "spec.gp.model"),
      gp(
          "GP lags over the limit", [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->set_input_lags(65); },
          C::kInvalidArgument, "spec.gp.model.output_lags/input_lags"),
      gp(
          "GP data both logged and as pairs",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->add_logged_outputs(1.0); }, C::kInvalidArgument,
          "spec.gp.model: give the training data either"),
      gp(
          "GP regressors of wrong width",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->mutable_regressors()->set_cols(3); },
          C::kInvalidArgument, "spec.gp.model.regressors"),
      gp(
          "GP targets fewer than regressors",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->mutable_targets()->RemoveLast(); },
          C::kInvalidArgument, "spec.gp.model.targets"),
      gp(
          "GP points over the limit",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->mutable_regressors()->set_rows(5001); },
          C::kResourceExhausted, "spec.gp.model.regressors.rows"),
      gp(
          "GP kernel length scales of wrong length",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->mutable_kernel()->add_length_scales(1.0); },
          C::kInvalidArgument, "spec.gp.model.kernel.length_scales"),
      gp(
          "GP kernel with zero noise",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_model()->mutable_kernel()->set_noise_variance(0.0); },
          C::kInvalidArgument, "spec.gp.model.kernel.noise_variance"),
      gp(
          "GP zero horizon", [](v1::ProblemSpec* s) { s->mutable_gp()->set_horizon(0); }, C::kInvalidArgument,
          "spec.gp.horizon"),
      gp(
          "GP horizon over the limit", [](v1::ProblemSpec* s) { s->mutable_gp()->set_horizon(10001); },
          C::kResourceExhausted, "spec.gp.horizon"),
      gp(
          "GP zero output weight", [](v1::ProblemSpec* s) { s->mutable_gp()->set_output_weight(0.0); },
          C::kInvalidArgument, "spec.gp.output_weight"),
      gp(
          "GP input bounds crossed", [](v1::ProblemSpec* s) { s->mutable_gp()->set_input_min(2.0); },
          C::kInvalidArgument, "spec.gp.input_max"),
      gp(
          "GP rate bounds not bracketing zero", [](v1::ProblemSpec* s) { s->mutable_gp()->set_rate_min(0.1); },
          C::kInvalidArgument, "spec.gp.rate_min/rate_max"),
      gp(
          "GP output bounds crossed", [](v1::ProblemSpec* s) { s->mutable_gp()->set_output_max(-20.0); },
          C::kInvalidArgument, "spec.gp.output_max"),
      gp(
          "GP negative sigma multiple", [](v1::ProblemSpec* s) { s->mutable_gp()->set_sigma_multiple(-1.0); },
          C::kInvalidArgument, "spec.gp.sigma_multiple"),
      gp(
          "GP infinite input bound", [](v1::ProblemSpec* s) { s->mutable_gp()->set_input_max(kInf); },
          C::kInvalidArgument, "spec.gp.input_max"),
      gp(
          "GP SCP iterations over the limit",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_scp()->set_max_iterations(10001); }, C::kInvalidArgument,
          "spec.gp.scp.max_iterations"),
      gp(
          "GP negative SCP penalty", [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_scp()->set_penalty(-1.0); },
          C::kInvalidArgument, "spec.gp.scp.penalty"),
      gp(
          "GP trust radius below the stopping radius",
          [](v1::ProblemSpec* s) { s->mutable_gp()->mutable_scp()->set_initial_trust_radius(1e-9); },
          C::kInvalidArgument, "spec.gp.scp.initial_trust_radius"),
      gp(
          "GP reference of wrong length",
          [](v1::ProblemSpec* s) {
            s->mutable_gp()->add_reference(0.0);
            s->mutable_gp()->add_reference(0.0);
          },
          C::kInvalidArgument, "spec.gp.reference"),
      gp(
          "GP with an initial covariance",
          [](v1::ProblemSpec* s) {
            SetMatrix(s->mutable_initial_state()->mutable_covariance(), 2, 2, {1, 0, 0, 1});
          },
          C::kInvalidArgument, "spec.initial_state.covariance"),
      gp(
          "GP past window of wrong length", [](v1::ProblemSpec* s) { s->mutable_initial_state()->add_mean(0.0); },
          C::kInvalidArgument, "spec.initial_state.mean"),
  };
}

class HostileSpecRulesTest : public HostileCatalogueTest {
 protected:
  // Each rule broken: SolveOnce and CreateSession refuse it alike, nothing is created, and
  // the healthy session is unharmed.
  void ExpectEveryRuleRefused(const std::vector<SpecRule>& rules, const std::string& hostile_class) {
    const v1::ProblemSpec gp_spec = GpSpec();
    ASSERT_TRUE(client_->SolveOnce(gp_spec).ok()) << "the GP cases' base spec must be valid";
    const int sessions = server_->state().registry.size();
    for (const SpecRule& r : rules) {
      SCOPED_TRACE(r.rule);
      v1::ProblemSpec bad = r.gp ? gp_spec : spec_;
      r.mutate(&bad);
      ExpectRefused(client_->SolveOnce(bad).status(), r.code, r.field);
      ExpectRefused(client_->CreateSession(bad).status(), r.code, r.field);
      EXPECT_EQ(server_->state().registry.size(), sessions) << "a refused spec left a session";
      ExpectServerUnharmed();
    }
    CountCases(hostile_class, static_cast<int>(rules.size()));
  }
};

TEST_F(HostileSpecRulesTest, EveryRuleOfTheModelTheInitialStateAndTheTerminalCost) {
  ExpectEveryRuleRefused(ModelRules(), "spec rules: model, initial state, terminal cost");
}

TEST_F(HostileSpecRulesTest, EveryRuleOfAPrior) { ExpectEveryRuleRefused(PriorRules(), "spec rules: priors"); }

TEST_F(HostileSpecRulesTest, EveryRuleOfTheOptions) { ExpectEveryRuleRefused(OptionRules(), "spec rules: options"); }

TEST_F(HostileSpecRulesTest, EveryRuleOfMultiLevelInputsAndInputDifferences) {
  ExpectEveryRuleRefused(InputMapRules(), "spec rules: input levels and differences");
}

TEST_F(HostileSpecRulesTest, EveryRuleOfKeepOutRegions) {
  ExpectEveryRuleRefused(KeepOutRules(), "spec rules: keep-out");
}

TEST_F(HostileSpecRulesTest, EveryRuleOfAGpSpec) { ExpectEveryRuleRefused(GpRules(), "spec rules: GP"); }

// FitGpModel's request: the GP spec's model, one rule broken at a time.
TEST_F(HostileSpecRulesTest, EveryRuleOfAFitGpModelRequest) {
  v1::FitGpModelRequest valid;
  *valid.mutable_model() = GpSpec().gp().model();
  ASSERT_TRUE(client_->FitGpModel(valid).ok()) << "the cases' base request must be valid";
  struct Rule {
    const char* rule;
    std::function<void(v1::FitGpModelRequest*)> mutate;
    C code;
    const char* field;
  };
  const Rule rules[] = {
      {"no model", [](v1::FitGpModelRequest* r) { r->clear_model(); }, C::kInvalidArgument, "model: required"},
      {"iterations over the limit", [](v1::FitGpModelRequest* r) { r->set_max_iterations(100001); },
       C::kInvalidArgument, "max_iterations"},
      {"lags over the limit", [](v1::FitGpModelRequest* r) { r->mutable_model()->set_output_lags(65); },
       C::kInvalidArgument, "model.output_lags/input_lags"},
      {"data both logged and as pairs", [](v1::FitGpModelRequest* r) { r->mutable_model()->add_logged_inputs(0.0); },
       C::kInvalidArgument, "model: give the training data either"},
      {"logged inputs fewer than outputs",
       [](v1::FitGpModelRequest* r) {
         v1::GpModel* m = r->mutable_model();
         m->clear_regressors();
         m->clear_targets();
         for (int i = 0; i < 10; ++i) m->add_logged_outputs(0.1 * i);
         for (int i = 0; i < 9; ++i) m->add_logged_inputs(0.0);
       },
       C::kInvalidArgument, "model.logged_inputs"},
      {"too few logged samples for the lags",
       [](v1::FitGpModelRequest* r) {
         v1::GpModel* m = r->mutable_model();
         m->clear_regressors();
         m->clear_targets();
         m->add_logged_outputs(1.0);
         m->add_logged_inputs(0.0);
       },
       C::kInvalidArgument, "model.logged_outputs"},
      {"points over the limit",
       [](v1::FitGpModelRequest* r) { r->mutable_model()->mutable_regressors()->set_rows(5001); },
       C::kResourceExhausted, "model.regressors.rows"},
      {"regressors data short",
       [](v1::FitGpModelRequest* r) { r->mutable_model()->mutable_regressors()->mutable_data()->RemoveLast(); },
       C::kInvalidArgument, "model.regressors.data"},
      {"starting kernel with a negative signal variance",
       [](v1::FitGpModelRequest* r) { r->mutable_model()->mutable_kernel()->set_signal_variance(-1.0); },
       C::kInvalidArgument, "model.kernel.signal_variance"},
  };
  for (const Rule& r : rules) {
    SCOPED_TRACE(r.rule);
    v1::FitGpModelRequest bad = valid;
    r.mutate(&bad);
    ExpectRefused(client_->FitGpModel(bad).status(), r.code, r.field);
    ExpectServerUnharmed();
  }
  CountCases("FitGpModel rules", static_cast<int>(std::size(rules)));
}

// A step that breaks a rule on `session`, which must answer `reference` again afterwards.
struct StepRule {
  const char* rule;
  std::function<void(v1::Step*)> mutate;
  C code;
  const char* field;
};

v1::PriorUpdate::Entry* UpdateEntry(google::protobuf::RepeatedPtrField<v1::PriorUpdate::Entry>* entries, int index,
                                    v1::PriorKind kind) {
  v1::PriorUpdate::Entry* e = entries->Add();
  e->set_index(index);
  Fresh(e->mutable_prior(), kind);
  return e;
}

std::vector<StepRule> StepRules() {
  return {
      {"unknown warm start", [](v1::Step* s) { s->set_warm_start(static_cast<v1::WarmStart>(42)); },
       C::kInvalidArgument, "step.warm_start"},
      {"negative time limit", [](v1::Step* s) { s->set_time_limit_ms(-1.0); }, C::kInvalidArgument,
       "step.time_limit_ms"},
      {"iteration cap beyond an int", [](v1::Step* s) { s->set_max_iterations(3'000'000'000u); }, C::kInvalidArgument,
       "step.max_iterations"},
      {"state of wrong length", [](v1::Step* s) { s->mutable_state()->RemoveLast(); }, C::kFailedPrecondition,
       "step.state"},
      {"previous input without input differences", [](v1::Step* s) { s->add_previous_input(0.0); }, C::kInvalidArgument,
       "step.previous_input"},
      {"reference on a linear session", [](v1::Step* s) { s->add_reference(0.0); }, C::kInvalidArgument,
       "step.reference"},
      {"update of an input that does not exist", [](v1::Step* s) { s->mutable_update()->add_inputs()->set_index(3); },
       C::kInvalidArgument, "step.update.inputs[0].index"},
      {"update of an output that does not exist",
       [](v1::Step* s) { s->mutable_update()->add_outputs()->set_index(4'000'000'000u); }, C::kInvalidArgument,
       "step.update.outputs[0].index = 4000000000: must be"},  // echoed as sent, not clamped to an int
      {"update with a per-step array of wrong length",
       [](v1::Step* s) {
         auto* e = UpdateEntry(s->mutable_update()->mutable_inputs(), 0, v1::PRIOR_KIND_UNSPECIFIED);
         for (int i = 0; i < 4; ++i) e->mutable_prior()->add_target(0.0);
       },
       C::kInvalidArgument, "step.update.inputs[0].prior.target"},
      {"update with an unknown kind",
       [](v1::Step* s) { UpdateEntry(s->mutable_update()->mutable_outputs(), 1, static_cast<v1::PriorKind>(77)); },
       C::kInvalidArgument, "step.update.outputs[0].prior.kind"},
      {"update with lower above upper",
       [](v1::Step* s) {
         auto* e = UpdateEntry(s->mutable_update()->mutable_outputs(), 2, v1::PRIOR_KIND_BOX);
         e->mutable_prior()->add_lower(1.0);
         e->mutable_prior()->add_upper(0.0);
       },
       C::kInvalidArgument, "step.update.outputs[0].prior at step 0"},
      {"update with a BINARY of one level",
       [](v1::Step* s) {
         UpdateEntry(s->mutable_update()->mutable_inputs(), 1, v1::PRIOR_KIND_BINARY)->mutable_prior()->add_upper(1.0);
       },
       C::kInvalidArgument, "step.update.inputs[0].prior: BINARY"},
      {"valid update after an invalid one",
       [](v1::Step* s) {
         UpdateEntry(s->mutable_update()->mutable_inputs(), 0, v1::PRIOR_KIND_UNSPECIFIED);
         UpdateEntry(s->mutable_update()->mutable_inputs(), 1, v1::PRIOR_KIND_L1);  // no slope
       },
       C::kInvalidArgument, "step.update.inputs[1].prior.slope"},
  };
}

TEST_F(HostileSpecRulesTest, EveryRuleOfAStepLeavesTheSessionAsItWas) {
  auto created = client_->CreateSession(spec_);
  ASSERT_TRUE(created.ok()) << created.status();
  const std::string id = created->session_id();
  const std::vector<StepRule> rules = StepRules();
  for (const StepRule& r : rules) {
    SCOPED_TRACE(r.rule);
    v1::Step bad = StateStep(4);
    r.mutate(&bad);
    ExpectRefused(client_->Solve(id, bad).status(), r.code, r.field);
    auto again = client_->Solve(id, StateStep(4));  // the spec's priors, as the healthy session's
    ASSERT_TRUE(again.ok()) << again.status();
    ExpectHealthyPlan(*again);
    ExpectServerUnharmed();
  }
  CountCases("step rules", static_cast<int>(rules.size()));
}

// Sessions whose inputs are mapped (levels, differences) refuse what their map fixes.
TEST_F(HostileSpecRulesTest, StepRulesOfSessionsWithMappedInputs) {
  v1::ProblemSpec levels = spec_, differences = spec_;
  ThreeLevelInput(&levels);
  InputDifferences(&differences);
  struct Case {
    const char* rule;
    const v1::ProblemSpec* spec;
    std::function<void(v1::Step*)> mutate;
    C code;
    const char* field;
  };
  const Case cases[] = {
      {"input update on a multi-level session", &levels,
       [](v1::Step* s) { UpdateEntry(s->mutable_update()->mutable_inputs(), 1, v1::PRIOR_KIND_UNSPECIFIED); },
       C::kFailedPrecondition, "step.update.inputs"},
      {"previous input of wrong length", &differences, [](v1::Step* s) { s->add_previous_input(0.0); },
       C::kFailedPrecondition, "step.previous_input"},
      {"infinite previous input", &differences,
       [](v1::Step* s) {
         for (double u : {0.0, kInf, 0.0}) s->add_previous_input(u);
       },
       C::kInvalidArgument, "step.previous_input[1]"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.rule);
    auto created = client_->CreateSession(*c.spec);
    ASSERT_TRUE(created.ok()) << created.status();
    // u[-1] given: otherwise each step takes the previous plan's u[0] and plans differently.
    v1::Step good = StateStep(4);
    if (c.spec == &differences) good.mutable_previous_input()->Resize(3, 0.0);
    auto reference = client_->Solve(created->session_id(), good);
    ASSERT_TRUE(reference.ok()) << reference.status();
    v1::Step bad = StateStep(4);
    c.mutate(&bad);
    ExpectRefused(client_->Solve(created->session_id(), bad).status(), c.code, c.field);
    auto again = client_->Solve(created->session_id(), good);
    ASSERT_TRUE(again.ok()) << again.status();
    EXPECT_EQ(again->objective(), reference->objective()) << "a refused step changed the session";
    ASSERT_TRUE(client_->CloseSession(created->session_id()).ok());
    ExpectServerUnharmed();
  }
  CountCases("step rules: mapped inputs", static_cast<int>(std::size(cases)));
}

}  // namespace
}  // namespace nupmpc::testing
