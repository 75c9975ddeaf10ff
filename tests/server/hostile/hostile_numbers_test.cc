// The hostile-input catalogue's numeric class: NaN, +Inf and -Inf in every
// numeric field kind of a spec and of a step, denormal and huge finite values, and
// dimensions whose product is a memory bomb while each is within its limit. Every case
// gets its code and a message naming the field; after each one a healthy session still
// answers with the bit-identical plan and the server's resident memory has not jumped
// (tests/server/hostile/hostile_catalogue.h).
#include <cmath>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "tests/server/hostile/hostile_catalogue.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;
using C = absl::StatusCode;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Writes `value` into one numeric field of a masses_N30 spec (12 states, 3 inputs, 12
// outputs, N = 30, box priors on inputs and outputs, a terminal cost).
struct SpecField {
  const char* field;  // as the server names it
  std::function<void(v1::ProblemSpec*, double)> set;
  bool infinity_means_unbounded_below = false;  // lower bounds: -Inf is "no bound"
  bool infinity_means_unbounded_above = false;  // upper bounds: +Inf is "no bound"
};

std::vector<SpecField> SpecFields() {
  return {
      {"spec.model.a[0].data[7]",
       [](v1::ProblemSpec* s, double v) { s->mutable_model()->mutable_a(0)->set_data(7, v); }},
      {"spec.model.b[0].data[2]",
       [](v1::ProblemSpec* s, double v) { s->mutable_model()->mutable_b(0)->set_data(2, v); }},
      {"spec.model.c[0].data[13]",
       [](v1::ProblemSpec* s, double v) { s->mutable_model()->mutable_c(0)->set_data(13, v); }},
      {"spec.model.state_offset[4]",
       [](v1::ProblemSpec* s, double v) {
         for (int i = 0; i < 12; ++i) s->mutable_model()->add_state_offset(i == 4 ? v : 0.0);
       }},
      {"spec.model.output_offset[5]",
       [](v1::ProblemSpec* s, double v) {
         for (int i = 0; i < 12; ++i) s->mutable_model()->add_output_offset(i == 5 ? v : 0.0);
       }},
      {"spec.initial_state.mean", [](v1::ProblemSpec* s, double v) { s->mutable_initial_state()->set_mean(9, v); }},
      {"spec.initial_state.covariance",
       [](v1::ProblemSpec* s, double v) {
         v1::Matrix* cov = s->mutable_initial_state()->mutable_covariance();
         cov->set_rows(12);
         cov->set_cols(12);
         for (int i = 0; i < 144; ++i) cov->add_data(i % 13 == 0 ? 1.0 : 0.0);
         cov->set_data(26, v);
       }},
      {"spec.input_priors[1].lower", [](v1::ProblemSpec* s, double v) { s->mutable_input_priors(1)->set_lower(0, v); },
       true, false},
      {"spec.input_priors[2].upper", [](v1::ProblemSpec* s, double v) { s->mutable_input_priors(2)->set_upper(0, v); },
       false, true},
      {"spec.input_priors[0].weight",
       [](v1::ProblemSpec* s, double v) { s->mutable_input_priors(0)->set_weight(0, v); }},
      {"spec.input_priors[0].target", [](v1::ProblemSpec* s, double v) { s->mutable_input_priors(0)->add_target(v); }},
      {"spec.output_priors[3].lower",
       [](v1::ProblemSpec* s, double v) { s->mutable_output_priors(3)->set_lower(0, v); }, true, false},
      {"spec.output_priors[4].upper",
       [](v1::ProblemSpec* s, double v) { s->mutable_output_priors(4)->set_upper(0, v); }, false, true},
      {"spec.output_priors[5].weight",
       [](v1::ProblemSpec* s, double v) { s->mutable_output_priors(5)->set_weight(0, v); }},
      {"spec.terminal.weight",
       [](v1::ProblemSpec* s, double v) { s->mutable_terminal()->mutable_weight()->set_data(0, v); }},
      {"spec.terminal.target", [](v1::ProblemSpec* s, double v) { s->mutable_terminal()->set_target(3, v); }},
      {"spec.options.objective_tolerance",
       [](v1::ProblemSpec* s, double v) { s->mutable_options()->set_objective_tolerance(v); }},
      {"spec.options.violation_tolerance",
       [](v1::ProblemSpec* s, double v) { s->mutable_options()->set_violation_tolerance(v); }},
      {"spec.options.time_limit_ms", [](v1::ProblemSpec* s, double v) { s->mutable_options()->set_time_limit_ms(v); }},
      {"spec.options.elastic_slope", [](v1::ProblemSpec* s, double v) { s->mutable_options()->set_elastic_slope(v); }},
  };
}

struct StepField {
  const char* field;
  std::function<void(v1::Step*, double)> set;
  bool infinity_means_unbounded_below = false;
  bool infinity_means_unbounded_above = false;
};

std::vector<StepField> StepFields() {
  const auto output_box = [](v1::Step* s, double lower, double upper) {
    auto* e = s->mutable_update()->add_outputs();
    e->set_index(2);
    e->mutable_prior()->set_kind(v1::PRIOR_KIND_BOX);
    e->mutable_prior()->add_lower(lower);
    e->mutable_prior()->add_upper(upper);
  };
  return {
      {"step.state[6]", [](v1::Step* s, double v) { s->set_state(6, v); }},
      {"step.time_limit_ms", [](v1::Step* s, double v) { s->set_time_limit_ms(v); }},
      {"step.update.outputs[0].prior.lower", [=](v1::Step* s, double v) { output_box(s, v, 4.0); }, true, false},
      {"step.update.outputs[0].prior.upper", [=](v1::Step* s, double v) { output_box(s, -4.0, v); }, false, true},
      {"step.update.inputs[0].prior.target",
       [](v1::Step* s, double v) {
         auto* e = s->mutable_update()->add_inputs();
         e->set_index(0);
         e->mutable_prior()->add_weight(1.0);
         e->mutable_prior()->add_target(v);
       }},
  };
}

// Whether `value` in a field is a legal number there: finite, or the infinity that means
// "no bound" on that side.
template <class Field>
bool Legal(const Field& f, double value) {
  if (std::isfinite(value)) return true;
  if (std::isnan(value)) return false;
  return value < 0 ? f.infinity_means_unbounded_below : f.infinity_means_unbounded_above;
}

const char* Name(double v) { return std::isnan(v) ? "NaN" : v > 0 ? "+Inf" : "-Inf"; }

// What the refusal names: the field, except for an infinity on the wrong side of a bound,
// which the server refuses as a pair ("spec.input_priors[1] at step 0: bounds [inf, 0.5]
// leave no feasible value") and names by the prior.
template <class Field>
std::string NamedField(const Field& f, double value) {
  const std::string field = f.field;
  const bool bound = f.infinity_means_unbounded_below || f.infinity_means_unbounded_above;
  if (bound && std::isinf(value)) return field.substr(0, field.rfind('.'));
  return field;
}

class HostileNumbersTest : public HostileCatalogueTest {};

TEST_F(HostileNumbersTest, NanAndInfinitiesInEverySpecFieldKind) {
  int refused = 0, accepted = 0;
  for (const SpecField& f : SpecFields()) {
    for (const double value : {kNaN, kInf, -kInf}) {
      SCOPED_TRACE(std::string(f.field) + " = " + Name(value));
      v1::ProblemSpec spec = spec_;
      f.set(&spec, value);
      absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
      if (Legal(f, value)) {
        ASSERT_TRUE(once.ok()) << once.status();
        ExpectFinite(*once);
        ++accepted;
      } else {
        EXPECT_EQ(once.status().code(), C::kInvalidArgument) << once.status();
        EXPECT_THAT(std::string(once.status().message()), HasSubstr(NamedField(f, value)));
        EXPECT_EQ(client_->CreateSession(spec).status().code(), C::kInvalidArgument);
        ++refused;
      }
      ExpectServerUnharmed();
    }
  }
  std::printf("spec fields: %d refused, %d accepted (an infinity meaning no bound)\n", refused, accepted);
  EXPECT_GE(refused, 50);
  CountCases("numbers: NaN/Inf in a spec", refused + accepted);
}

TEST_F(HostileNumbersTest, NanAndInfinitiesInEveryStepFieldKindLeaveTheSessionAsItWas) {
  int refused = 0;
  for (const StepField& f : StepFields()) {
    for (const double value : {kNaN, kInf, -kInf}) {
      SCOPED_TRACE(std::string(f.field) + " = " + Name(value));
      auto created = client_->CreateSession(spec_);  // each case on a session of its own
      ASSERT_TRUE(created.ok());
      const std::string id = created->session_id();
      auto reference = client_->Solve(id, StateStep(7));
      ASSERT_TRUE(reference.ok());
      v1::Step step = StateStep(7);
      f.set(&step, value);
      absl::StatusOr<v1::SolveResult> r = client_->Solve(id, step);
      if (Legal(f, value)) {
        ASSERT_TRUE(r.ok()) << r.status();
        ExpectFinite(*r);
      } else {
        ++refused;
        EXPECT_EQ(r.status().code(), C::kInvalidArgument) << r.status();
        EXPECT_THAT(std::string(r.status().message()), HasSubstr(NamedField(f, value)));
        auto again = client_->Solve(id, StateStep(7));
        ASSERT_TRUE(again.ok());
        EXPECT_EQ(again->objective(), reference->objective()) << "a refused step changed the session";
      }
      ASSERT_TRUE(client_->CloseSession(id).ok());
      ExpectServerUnharmed();
    }
  }
  EXPECT_GE(refused, 12);
  CountCases("numbers: NaN/Inf in a step", static_cast<int>(StepFields().size()) * 3);
}

TEST_F(HostileNumbersTest, DenormalAndHugeFiniteNumbersNeverLeaveTheServerAsNanOrInf) {
  int cases = 0;
  for (const SpecField& f : SpecFields()) {
    for (const double value : {std::numeric_limits<double>::denorm_min(), 1e-300, 1e300, -1e300}) {
      SCOPED_TRACE(std::string(f.field) + " = " + std::to_string(value));
      ++cases;
      v1::ProblemSpec spec = spec_;
      f.set(&spec, value);
      absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
      // Refused (with the field named) or solved: never a NaN or an infinity in the answer.
      if (once.ok()) {
        ExpectFinite(*once);
      } else {
        EXPECT_THAT(once.status().code(),
                    ::testing::AnyOf(C::kInvalidArgument, C::kFailedPrecondition, C::kResourceExhausted))
            << once.status();
        EXPECT_THAT(std::string(once.status().message()), HasSubstr("spec")) << once.status();
      }
      ExpectServerUnharmed();
    }
  }
  CountCases("numbers: denormal and huge", cases);
}

TEST_F(HostileNumbersTest, DimensionsWhoseProductIsAMemoryBombAreRefusedBeforeAllocating) {
  struct Bomb {
    const char* name;
    std::uint32_t states, inputs, horizon;
  };
  const Bomb bombs[] = {Bomb{"M at its limit, N at its limit", 1000, 1, 100000},
                        Bomb{"N at its limit, many inputs", 10, 1000, 100000}};
  for (const Bomb& b : bombs) {
    SCOPED_TRACE(b.name);
    v1::ProblemSpec spec;
    v1::Model* m = spec.mutable_model();
    m->set_num_states(b.states);
    m->set_num_inputs(b.inputs);
    m->set_num_outputs(0);
    m->set_horizon(b.horizon);
    v1::Matrix* a = m->add_a();
    a->set_rows(b.states);
    a->set_cols(b.states);
    a->mutable_data()->Resize(static_cast<int>(b.states * b.states), 0.0);
    v1::Matrix* bm = m->add_b();
    bm->set_rows(b.states);
    bm->set_cols(b.inputs);
    bm->mutable_data()->Resize(static_cast<int>(b.states * b.inputs), 0.0);
    spec.mutable_initial_state()->mutable_mean()->Resize(static_cast<int>(b.states), 0.0);
    for (std::uint32_t i = 0; i < b.inputs; ++i) spec.add_input_priors()->add_weight(1.0);
    const absl::Status once = client_->SolveOnce(spec).status();
    EXPECT_EQ(once.code(), C::kResourceExhausted) << once;
    EXPECT_THAT(std::string(once.message()), HasSubstr("spec")) << once;
    EXPECT_EQ(client_->CreateSession(spec).status().code(), C::kResourceExhausted);
    ExpectServerUnharmed();
  }
  CountCases("memory bombs", static_cast<int>(std::size(bombs)));
}

}  // namespace
}  // namespace nupmpc::testing
