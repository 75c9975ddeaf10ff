// Malformed and hostile requests: each gets the right code and a message naming the field,
// and the server keeps serving (a session that saw a rejected update solves as before).
#include <functional>
#include <limits>

#include "gmock/gmock.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

struct SpecCase {
  const char* name;
  std::function<void(v1::ProblemSpec*)> mutate;
  absl::StatusCode code;
  const char* field;  // must appear in the message
};

std::vector<SpecCase> SpecCases() {
  using C = absl::StatusCode;
  return {
      {"no model", [](v1::ProblemSpec* s) { s->clear_model(); }, C::kInvalidArgument, "spec.model"},
      {"zero states", [](v1::ProblemSpec* s) { s->mutable_model()->set_num_states(0); }, C::kInvalidArgument,
       "spec.model.num_states"},
      {"zero horizon", [](v1::ProblemSpec* s) { s->mutable_model()->set_horizon(0); }, C::kInvalidArgument,
       "spec.model.horizon"},
      {"horizon over the limit", [](v1::ProblemSpec* s) { s->mutable_model()->set_horizon(5'000'000); },
       C::kResourceExhausted, "spec.model.horizon"},
      {"A of wrong shape", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_a(0)->set_cols(11); },
       C::kInvalidArgument, "spec.model.a[0]"},
      {"A data too short", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_a(0)->mutable_data()->RemoveLast(); },
       C::kInvalidArgument, "spec.model.a[0].data"},
      {"NaN in A", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_a(0)->set_data(5, kNaN); }, C::kInvalidArgument,
       "spec.model.a[0].data[5]"},
      {"Inf in B", [](v1::ProblemSpec* s) { s->mutable_model()->mutable_b(0)->set_data(0, kInf); }, C::kInvalidArgument,
       "spec.model.b[0].data[0]"},
      {"two C matrices", [](v1::ProblemSpec* s) { *s->mutable_model()->add_c() = s->model().c(0); },
       C::kInvalidArgument, "spec.model.c"},
      {"state offset of wrong size", [](v1::ProblemSpec* s) { s->mutable_model()->add_state_offset(1.0); },
       C::kInvalidArgument, "spec.model.state_offset"},
      {"NaN state offset",
       [](v1::ProblemSpec* s) {
         for (int i = 0; i < 12; ++i) s->mutable_model()->add_state_offset(i == 3 ? kNaN : 0.0);
       },
       C::kInvalidArgument, "spec.model.state_offset[3]"},
      {"initial mean of wrong size", [](v1::ProblemSpec* s) { s->mutable_initial_state()->add_mean(0.0); },
       C::kInvalidArgument, "spec.initial_state.mean"},
      {"NaN initial mean", [](v1::ProblemSpec* s) { s->mutable_initial_state()->set_mean(2, kNaN); },
       C::kInvalidArgument, "spec.initial_state.mean"},
      {"covariance with NaN",
       [](v1::ProblemSpec* s) {
         v1::Matrix* cov = s->mutable_initial_state()->mutable_covariance();
         cov->set_rows(12);
         cov->set_cols(12);
         for (int i = 0; i < 144; ++i) cov->add_data(i % 13 == 0 ? 1.0 : 0.0);
         cov->set_data(0, kNaN);
       },
       C::kInvalidArgument, "spec.initial_state.covariance"},
      {"missing input prior", [](v1::ProblemSpec* s) { s->mutable_input_priors()->RemoveLast(); }, C::kInvalidArgument,
       "spec.input_priors"},
      {"negative weight", [](v1::ProblemSpec* s) { s->mutable_input_priors(0)->set_weight(0, -1.0); },
       C::kInvalidArgument, "spec.input_priors[0].weight"},
      {"NaN weight", [](v1::ProblemSpec* s) { s->mutable_input_priors(1)->set_weight(0, kNaN); }, C::kInvalidArgument,
       "spec.input_priors[1].weight"},
      {"NaN target", [](v1::ProblemSpec* s) { s->mutable_output_priors(2)->add_target(kNaN); }, C::kInvalidArgument,
       "spec.output_priors[2].target"},
      {"lower above upper",
       [](v1::ProblemSpec* s) {
         s->mutable_input_priors(0)->set_lower(0, 1.0);
         s->mutable_input_priors(0)->set_upper(0, -1.0);
       },
       C::kInvalidArgument, "spec.input_priors[0]"},
      {"NaN bound", [](v1::ProblemSpec* s) { s->mutable_input_priors(2)->set_upper(0, kNaN); }, C::kInvalidArgument,
       "spec.input_priors[2].upper"},
      {"per-step array of wrong length",
       [](v1::ProblemSpec* s) {
         s->mutable_output_priors(0)->clear_lower();
         for (int i = 0; i < 7; ++i) s->mutable_output_priors(0)->add_lower(-1.0);
       },
       C::kInvalidArgument, "spec.output_priors[0].lower"},
      {"L1 without slope",
       [](v1::ProblemSpec* s) {
         s->mutable_input_priors(0)->set_kind(v1::PRIOR_KIND_L1);
         s->mutable_input_priors(0)->clear_slope();
       },
       C::kInvalidArgument, "spec.input_priors[0].slope"},
      {"negative slope", [](v1::ProblemSpec* s) { s->mutable_input_priors(0)->add_slope(-2.0); }, C::kInvalidArgument,
       "spec.input_priors[0].slope"},
      {"binary with one level",
       [](v1::ProblemSpec* s) {
         auto* c = s->mutable_input_priors(1);
         c->set_kind(v1::PRIOR_KIND_BINARY);
         c->clear_lower();
         c->clear_upper();
         c->add_lower(0.0);
       },
       C::kInvalidArgument, "spec.input_priors[1]: BINARY needs both levels"},
      {"Lp exponent above one",
       [](v1::ProblemSpec* s) {
         auto* c = s->mutable_input_priors(2);
         c->set_kind(v1::PRIOR_KIND_LP);
         c->clear_slope();
         c->add_slope(1.0);
         c->add_exponent(1.5);
       },
       C::kInvalidArgument, "spec.input_priors[2].exponent"},
      {"unknown estimation",
       [](v1::ProblemSpec* s) { s->mutable_input_priors(0)->set_estimation(static_cast<v1::Estimation>(7)); },
       C::kInvalidArgument, "spec.input_priors[0].estimation"},
      {"unknown prior kind",
       [](v1::ProblemSpec* s) { s->mutable_input_priors(0)->set_kind(static_cast<v1::PriorKind>(42)); },
       C::kInvalidArgument, "spec.input_priors[0].kind"},
      {"asymmetric terminal weight",
       [](v1::ProblemSpec* s) { s->mutable_terminal()->mutable_weight()->set_data(1, 123.0); }, C::kInvalidArgument,
       "spec.terminal.weight"},
      {"NaN terminal target", [](v1::ProblemSpec* s) { s->mutable_terminal()->set_target(0, kNaN); },
       C::kInvalidArgument, "spec.terminal.target"},
      {"iteration cap over the limit", [](v1::ProblemSpec* s) { s->mutable_options()->set_max_iterations(1u << 30); },
       C::kResourceExhausted, "spec.options.max_iterations"},
      {"negative tolerance", [](v1::ProblemSpec* s) { s->mutable_options()->set_objective_tolerance(-1.0); },
       C::kInvalidArgument, "spec.options.objective_tolerance"},
      {"unknown algorithm",
       [](v1::ProblemSpec* s) { s->mutable_options()->set_algorithm(static_cast<v1::Algorithm>(99)); },
       C::kInvalidArgument, "spec.options.algorithm"},
      {"forced algorithm that cannot handle output bounds",
       [](v1::ProblemSpec* s) { s->mutable_options()->set_algorithm(v1::ALGORITHM_IBFFD); }, C::kFailedPrecondition,
       "spec:"},
  };
}

class ServiceValidationTest : public ServiceTest {
 protected:
  void SetUp() override {
    ServiceTest::SetUp();
    instance_ = LoadInstanceOrDie("masses_N30");
    spec_ = SpecOrDie(instance_.problem);
  }
  v1::Step StateStep(int t) const {
    v1::Step step;
    const Eigen::VectorXd& x = instance_.closed_loop->x1[t];
    step.mutable_state()->Add(x.data(), x.data() + x.size());
    step.set_warm_start(v1::WARM_START_COLD);
    return step;
  }
  bench::BenchmarkInstance instance_;
  v1::ProblemSpec spec_;
};

TEST_F(ServiceValidationTest, EveryMalformedSpecIsRejectedWithTheFieldNamed) {
  // A healthy session solved before and after proves the server keeps serving it.
  auto healthy = client_->CreateSession(spec_);
  ASSERT_TRUE(healthy.ok()) << healthy.status();
  auto before = client_->Solve(healthy->session_id(), StateStep(3));
  ASSERT_TRUE(before.ok());
  const std::vector<SpecCase> cases = SpecCases();
  ASSERT_GE(cases.size(), 25u);
  for (const SpecCase& c : cases) {
    SCOPED_TRACE(c.name);
    v1::ProblemSpec bad = spec_;
    c.mutate(&bad);
    const absl::Status once = client_->SolveOnce(bad).status();
    EXPECT_EQ(once.code(), c.code) << once;
    EXPECT_THAT(std::string(once.message()), HasSubstr(c.field));
    const absl::Status create = client_->CreateSession(bad).status();
    EXPECT_EQ(create.code(), c.code) << create;
  }
  auto after = client_->Solve(healthy->session_id(), StateStep(3));
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_EQ(after->objective(), before->objective());
}

TEST_F(ServiceValidationTest, BadStepsLeaveTheSessionAsItWas) {
  auto created = client_->CreateSession(spec_);
  ASSERT_TRUE(created.ok());
  const std::string id = created->session_id();
  auto reference = client_->Solve(id, StateStep(5));
  ASSERT_TRUE(reference.ok());

  struct StepCase {
    const char* name;
    std::function<void(v1::Step*)> mutate;
    absl::StatusCode code;
    const char* field;
  };
  const std::vector<StepCase> cases = {
      {"state of wrong size", [](v1::Step* s) { s->mutable_state()->RemoveLast(); },
       absl::StatusCode::kFailedPrecondition, "step.state"},
      {"NaN state", [](v1::Step* s) { s->set_state(0, kNaN); }, absl::StatusCode::kInvalidArgument, "step.state[0]"},
      {"update of an input that does not exist", [](v1::Step* s) { s->mutable_update()->add_inputs()->set_index(7); },
       absl::StatusCode::kInvalidArgument, "step.update.inputs[0].index"},
      {"NaN bound in an update",
       [](v1::Step* s) {
         auto* e = s->mutable_update()->add_outputs();
         e->set_index(1);
         e->mutable_prior()->set_kind(v1::PRIOR_KIND_BOX);
         e->mutable_prior()->add_lower(-1.0);
         e->mutable_prior()->add_upper(kNaN);
       },
       absl::StatusCode::kInvalidArgument, "step.update.outputs[0].prior.upper"},
      {"NaN slope in an update",
       [](v1::Step* s) {
         auto* e = s->mutable_update()->add_inputs();
         e->set_index(0);
         e->mutable_prior()->set_kind(v1::PRIOR_KIND_L1);
         e->mutable_prior()->add_weight(1.0);
         e->mutable_prior()->add_target(0.0);
         e->mutable_prior()->add_slope(kNaN);
       },
       absl::StatusCode::kInvalidArgument, "step.update.inputs[0].prior.slope"},
      {"NaN radius in an update",
       [](v1::Step* s) {
         auto* e = s->mutable_update()->add_inputs();
         e->set_index(1);
         e->mutable_prior()->set_kind(v1::PRIOR_KIND_HUBER);
         e->mutable_prior()->add_weight(1.0);
         e->mutable_prior()->add_target(0.0);
         e->mutable_prior()->add_slope(1.0);
         e->mutable_prior()->add_radius(kNaN);
       },
       absl::StatusCode::kInvalidArgument, "step.update.inputs[0].prior.radius"},
      {"NaN weight in an update",
       [](v1::Step* s) {
         auto* e = s->mutable_update()->add_outputs();
         e->set_index(0);
         e->mutable_prior()->add_weight(kNaN);
         e->mutable_prior()->add_target(0.0);
       },
       absl::StatusCode::kInvalidArgument, "step.update.outputs[0].prior.weight"},
      {"negative time limit", [](v1::Step* s) { s->set_time_limit_ms(-1.0); }, absl::StatusCode::kInvalidArgument,
       "step.time_limit_ms"},
      {"NaN time limit", [](v1::Step* s) { s->set_time_limit_ms(kNaN); }, absl::StatusCode::kInvalidArgument,
       "step.time_limit_ms"},
      {"unknown warm-start mode", [](v1::Step* s) { s->set_warm_start(static_cast<v1::WarmStart>(42)); },
       absl::StatusCode::kInvalidArgument, "step.warm_start"},
  };
  for (const StepCase& c : cases) {
    SCOPED_TRACE(c.name);
    v1::Step bad = StateStep(5);
    c.mutate(&bad);
    const absl::Status s = client_->Solve(id, bad).status();
    EXPECT_EQ(s.code(), c.code) << s;
    EXPECT_THAT(std::string(s.message()), HasSubstr(c.field));
  }
  auto again = client_->Solve(id, StateStep(5));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->objective(), reference->objective());  // bit-identical: nothing of the bad steps stuck
}

TEST_F(ServiceValidationTest, UnknownClosedAndForeignSessionsAreRefused) {
  EXPECT_EQ(client_->Solve("00000000000000000000000000000000", StateStep(0)).status().code(),
            absl::StatusCode::kNotFound);
  EXPECT_EQ(client_->GetSession("0123456789abcdef0123456789abcdef").status().code(), absl::StatusCode::kNotFound);
  // Malformed ids are refused before any lookup, and never echoed beyond a short prefix.
  const std::string long_id(20000, 'a');
  const absl::Status malformed = client_->CloseSession(long_id);
  EXPECT_EQ(malformed.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(malformed.message()), HasSubstr("32 hex digits"));
  EXPECT_LT(malformed.message().size(), 200u);
  EXPECT_EQ(client_->GetSession("nope").status().code(), absl::StatusCode::kInvalidArgument);
  auto created = client_->CreateSession(spec_);
  ASSERT_TRUE(created.ok());
  EXPECT_EQ(created->session_id().size(), 32u);  // 128 random bits in hex
  ASSERT_TRUE(client_->CloseSession(created->session_id()).ok());
  EXPECT_EQ(client_->CloseSession(created->session_id()).code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(client_->Solve(created->session_id(), StateStep(0)).status().code(), absl::StatusCode::kNotFound);

  // A stream-owned session cannot be attached to, solved or closed from elsewhere.
  auto owned = client_->OpenSession(spec_);
  ASSERT_TRUE(owned.ok());
  const std::string owned_id = (*owned)->id();
  EXPECT_EQ(client_->Solve(owned_id, StateStep(0)).status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(client_->CloseSession(owned_id).code(), absl::StatusCode::kFailedPrecondition);
  grpc::ClientContext context;
  auto intruder = client_->stub().Control(&context);
  v1::ControlRequest attach;
  attach.set_session_id(owned_id);
  ASSERT_TRUE(intruder->Write(attach));
  v1::ControlResponse ignored;
  while (intruder->Read(&ignored)) {
  }
  const grpc::Status refused = intruder->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_THAT(refused.error_message(), HasSubstr("session_id"));
  // The owner is unaffected.
  EXPECT_TRUE((*owned)->Step(StateStep(0)).ok());
}

TEST_F(ServiceValidationTest, BadControlMessagesAreAnsweredAndTheStreamStaysUsable) {
  grpc::ClientContext context;
  auto stream = client_->stub().Control(&context);
  v1::ControlRequest no_attach;
  no_attach.set_sequence(1);
  ASSERT_TRUE(stream->Write(no_attach));
  v1::ControlResponse r;
  EXPECT_FALSE(stream->Read(&r));
  const grpc::Status s = stream->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("attach"));

  grpc::ClientContext context2;
  auto good = client_->stub().Control(&context2);
  v1::ControlRequest first;
  *first.mutable_spec() = spec_;
  ASSERT_TRUE(good->Write(first));
  ASSERT_TRUE(good->Read(&r));
  v1::ControlRequest bad;
  bad.set_sequence(2);
  *bad.mutable_step() = StateStep(0);
  bad.mutable_step()->set_state(4, kNaN);
  ASSERT_TRUE(good->Write(bad));
  ASSERT_TRUE(good->Read(&r));
  EXPECT_EQ(r.sequence(), 2u);
  EXPECT_EQ(r.error_code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_THAT(r.error_message(), HasSubstr("step.state[4]"));
  v1::ControlRequest reattach;
  reattach.set_sequence(3);
  reattach.set_session_id("x");
  ASSERT_TRUE(good->Write(reattach));
  ASSERT_TRUE(good->Read(&r));
  EXPECT_EQ(r.error_code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_THAT(r.error_message(), HasSubstr("attach"));
  v1::ControlRequest ok_step;
  ok_step.set_sequence(4);
  *ok_step.mutable_step() = StateStep(0);
  ASSERT_TRUE(good->Write(ok_step));
  ASSERT_TRUE(good->Read(&r));
  EXPECT_EQ(r.sequence(), 4u);
  EXPECT_EQ(r.result().status(), v1::SOLVE_STATUS_CONVERGED);
  good->WritesDone();
  EXPECT_TRUE(good->Finish().ok());
}

TEST_F(ServiceValidationTest, OversizedMessagesAndFullRegistriesAreResourceExhausted) {
  TearDown();
  server::ServerOptions options = DefaultOptions();
  options.max_message_bytes = 1 << 20;
  options.max_sessions = 2;
  StartServer(options);
  v1::ProblemSpec huge = spec_;
  for (int i = 0; i < 200000; ++i) huge.mutable_model()->add_output_offset(0.0);  // 1.6 MB
  EXPECT_EQ(client_->SolveOnce(huge).status().code(), absl::StatusCode::kResourceExhausted);
  ASSERT_TRUE(client_->CreateSession(spec_).ok());
  ASSERT_TRUE(client_->CreateSession(spec_).ok());
  const absl::Status full = client_->CreateSession(spec_).status();
  EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(full.message()), HasSubstr("sessions"));
  auto info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok());
  EXPECT_GE(info->errors_by_code().at("RESOURCE_EXHAUSTED"), 1u);
  EXPECT_EQ(info->active_sessions(), 2u);
}

}  // namespace
}  // namespace nupmpc::testing
