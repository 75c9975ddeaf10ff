// The hostile-input catalogue's Control-stream class: violations of the
// stream's protocol. A first message that attaches to nothing (a step before attaching, an
// empty message, a bad spec) ends the stream with the code and the field named; a later
// message that breaks a rule (opening or attaching again, no step, a bad step, bytes that
// do not parse) is answered with the code and the field in ControlResponse.error_* and the
// stream and its session go on as before; a half-close or cancel mid-way still answers or
// ends cleanly and closes the stream's session. After each case a healthy session answers
// with the bit-identical plan and resident memory has not jumped.
#include <chrono>
#include <functional>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "tests/server/hostile/hostile_catalogue.h"

namespace nupmpc::testing {
namespace {

using G = grpc::StatusCode;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

class HostileControlProtocolTest : public HostileCatalogueTest {
 protected:
  v1::ControlRequest Open() const {
    v1::ControlRequest r;
    *r.mutable_spec() = spec_;
    return r;
  }
  v1::ControlRequest Step(std::uint64_t sequence) const {
    v1::ControlRequest r;
    r.set_sequence(sequence);
    *r.mutable_step() = StateStep(4);
    return r;
  }
  // The stream's session answers a good step with the healthy session's plan.
  void ExpectStreamAnswersAsBefore(OpenStream* s, std::uint64_t sequence) {
    ASSERT_TRUE(s->stream->Write(Step(sequence)));
    v1::ControlResponse r;
    ASSERT_TRUE(s->stream->Read(&r));
    EXPECT_EQ(r.sequence(), sequence);
    ASSERT_EQ(r.error_code(), 0) << r.error_message();
    ExpectHealthyPlan(r.result());
  }
  // Until the server holds `sessions` sessions (a stream's own session closes when the
  // stream is done, which may lag the client's Finish).
  void ExpectSessionsBecome(int sessions) {
    for (int i = 0; i < 500 && server_->state().registry.size() != sessions; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_EQ(server_->state().registry.size(), sessions);
  }
};

TEST_F(HostileControlProtocolTest, AFirstMessageThatAttachesToNothingEndsTheStreamWithTheFieldNamed) {
  v1::ControlRequest step_first = Step(1);
  v1::ControlRequest empty;
  v1::ControlRequest sequence_only;
  sequence_only.set_sequence(7);
  v1::ControlRequest bad_spec = Open();
  bad_spec.mutable_spec()->mutable_model()->set_horizon(0);
  v1::ControlRequest huge_spec = Open();
  huge_spec.mutable_spec()->mutable_model()->set_horizon(10'000'000);
  v1::ControlRequest bad_spec_with_step = bad_spec;
  *bad_spec_with_step.mutable_step() = StateStep(4);
  struct Case {
    const char* violation;
    const v1::ControlRequest* first;
    G code;
    const char* field;
  };
  const Case cases[] = {
      {"a step before attaching", &step_first, G::INVALID_ARGUMENT, "attach"},
      {"an empty first message", &empty, G::INVALID_ARGUMENT, "attach"},
      {"a sequence number only", &sequence_only, G::INVALID_ARGUMENT, "attach"},
      {"a spec that breaks a rule", &bad_spec, G::INVALID_ARGUMENT, "spec.model.horizon"},
      {"a spec that breaks a rule, with a step", &bad_spec_with_step, G::INVALID_ARGUMENT, "spec.model.horizon"},
      {"a spec over a limit", &huge_spec, G::RESOURCE_EXHAUSTED, "spec.model.horizon"},
  };
  const int sessions = server_->state().registry.size();
  for (const Case& c : cases) {
    SCOPED_TRACE(c.violation);
    v1::ControlResponse answer;
    bool answered = false;
    std::unique_ptr<OpenStream> s = OpenControl(*c.first, &answer, &answered);
    EXPECT_FALSE(answered) << "answered: " << answer.ShortDebugString();
    ExpectRefused(EndStream(s.get()), c.code, c.field);
    EXPECT_EQ(server_->state().registry.size(), sessions);
    ExpectServerUnharmed();
  }
  // A stream half-closed before its first message ends cleanly with nothing created.
  {
    grpc::ClientContext context;
    auto stream = client_->stub().Control(&context);
    stream->WritesDone();
    v1::ControlResponse answer;
    EXPECT_FALSE(stream->Read(&answer));
    EXPECT_TRUE(stream->Finish().ok());
    EXPECT_EQ(server_->state().registry.size(), sessions);
    ExpectServerUnharmed();
  }
  CountCases("Control: first message", static_cast<int>(std::size(cases)) + 1);
}

TEST_F(HostileControlProtocolTest, ALaterMessageThatBreaksARuleIsAnsweredAndTheStreamGoesOn) {
  v1::ControlResponse hello;
  bool answered = false;
  std::unique_ptr<OpenStream> s = OpenControl(Open(), &hello, &answered);
  ASSERT_TRUE(answered);
  ASSERT_EQ(hello.session_id().size(), 32u);
  std::uint64_t sequence = 10;
  ExpectStreamAnswersAsBefore(s.get(), sequence++);

  struct Case {
    const char* violation;
    std::function<void(v1::ControlRequest*)> make;
    G code;
    const char* field;
  };
  const std::string other = hello.session_id();
  const Case cases[] = {
      {"opening again", [&](v1::ControlRequest* r) { *r->mutable_spec() = spec_; }, G::INVALID_ARGUMENT, "attach"},
      {"opening again, with a step",
       [&](v1::ControlRequest* r) {
         *r->mutable_spec() = spec_;
         *r->mutable_step() = StateStep(4);
       },
       G::INVALID_ARGUMENT, "attach"},
      {"attaching after opening", [&](v1::ControlRequest* r) { r->set_session_id(healthy_id_); }, G::INVALID_ARGUMENT,
       "attach"},
      {"attaching to its own session", [&](v1::ControlRequest* r) { r->set_session_id(other); }, G::INVALID_ARGUMENT,
       "attach"},
      {"no step", [](v1::ControlRequest*) {}, G::INVALID_ARGUMENT, "step"},
      {"a step that breaks a rule",
       [&](v1::ControlRequest* r) {
         *r->mutable_step() = StateStep(4);
         r->mutable_step()->set_state(0, kNaN);
       },
       G::INVALID_ARGUMENT, "step.state[0]"},
      {"a step of the wrong size",
       [&](v1::ControlRequest* r) {
         *r->mutable_step() = StateStep(4);
         r->mutable_step()->add_state(0.0);
       },
       G::FAILED_PRECONDITION, "step.state"},
      {"an update that breaks a rule",
       [&](v1::ControlRequest* r) {
         *r->mutable_step() = StateStep(4);
         r->mutable_step()->mutable_update()->add_outputs()->set_index(99);
       },
       G::INVALID_ARGUMENT, "step.update.outputs[0].index"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.violation);
    v1::ControlRequest bad;
    bad.set_sequence(sequence);
    c.make(&bad);
    ASSERT_TRUE(s->stream->Write(bad));
    v1::ControlResponse r;
    ASSERT_TRUE(s->stream->Read(&r));
    EXPECT_EQ(r.sequence(), sequence++);
    EXPECT_EQ(r.error_code(), static_cast<int>(c.code)) << r.error_message();
    EXPECT_THAT(r.error_message(), ::testing::HasSubstr(c.field));
    EXPECT_FALSE(r.has_result());
    ExpectStreamAnswersAsBefore(s.get(), sequence++);  // steps after an error
    ExpectServerUnharmed();
  }
  // Many errors unread in a row: each answered once, in order, then a good step.
  constexpr int kBurst = 64;
  for (int i = 0; i < kBurst; ++i) {
    v1::ControlRequest empty;
    empty.set_sequence(1000 + i);
    ASSERT_TRUE(s->stream->Write(empty));
  }
  for (int i = 0; i < kBurst; ++i) {
    v1::ControlResponse r;
    ASSERT_TRUE(s->stream->Read(&r));
    EXPECT_EQ(r.sequence(), 1000u + i);
    EXPECT_EQ(r.error_code(), static_cast<int>(G::INVALID_ARGUMENT));
  }
  ExpectStreamAnswersAsBefore(s.get(), sequence++);
  EXPECT_TRUE(EndStream(s.get()).ok());
  ExpectServerUnharmed();
  CountCases("Control: later messages", static_cast<int>(std::size(cases)) + 1);
}

// Bytes that do not parse after the first message: answered in the stream, which goes on.
TEST_F(HostileControlProtocolTest, AnUnparseableMessageMidStreamIsAnsweredAndTheStreamGoesOn) {
  RawControlStream stream(target_);
  std::string bytes;
  const auto read = [&](v1::ControlResponse* r) { return stream.Read(&bytes) && r->ParseFromString(bytes); };
  ASSERT_TRUE(stream.Write(Open().SerializeAsString()));
  v1::ControlResponse r;
  ASSERT_TRUE(read(&r));
  ASSERT_EQ(r.session_id().size(), 32u);
  const std::string garbage[] = {"\x0a\x02\xc3\x28", "\x1a\xff\xff\xff\xff\x0f", std::string(1000, '\x0b')};
  std::uint64_t sequence = 1;
  for (const std::string& g : garbage) {
    ASSERT_TRUE(stream.Write(g));
    ASSERT_TRUE(read(&r));
    EXPECT_EQ(r.error_code(), static_cast<int>(G::INVALID_ARGUMENT)) << r.error_message();
    EXPECT_THAT(r.error_message(), ::testing::HasSubstr("nupmpc.v1.ControlRequest"));
    ASSERT_TRUE(stream.Write(Step(sequence).SerializeAsString()));
    ASSERT_TRUE(read(&r));
    EXPECT_EQ(r.sequence(), sequence++);
    ASSERT_EQ(r.error_code(), 0) << r.error_message();
    ExpectHealthyPlan(r.result());
    ExpectServerUnharmed();
  }
  const grpc::Status status = stream.Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  CountCases("Control: unparseable message mid-stream", static_cast<int>(std::size(garbage)));
}

TEST_F(HostileControlProtocolTest, AStreamEndedMidWayAnswersOrEndsCleanlyAndClosesItsSession) {
  const int sessions = server_->state().registry.size();
  {  // half-closed with a step unanswered: the answer still comes
    v1::ControlResponse hello;
    bool answered = false;
    std::unique_ptr<OpenStream> s = OpenControl(Open(), &hello, &answered);
    ASSERT_TRUE(answered);
    ASSERT_TRUE(s->stream->Write(Step(1)));
    ASSERT_TRUE(s->stream->Write(Step(2)));
    s->stream->WritesDone();
    v1::ControlResponse r;
    std::vector<v1::ControlResponse> answers;
    while (s->stream->Read(&r)) answers.push_back(r);
    EXPECT_TRUE(s->stream->Finish().ok());
    ASSERT_FALSE(answers.empty());
    EXPECT_EQ(answers.back().sequence(), 2u);  // the newest step; an older one may be superseded
    ExpectHealthyPlan(answers.back().result());
    ExpectSessionsBecome(sessions);
    ExpectServerUnharmed();
  }
  {  // cancelled with a step in flight
    v1::ControlResponse hello;
    bool answered = false;
    std::unique_ptr<OpenStream> s = OpenControl(Open(), &hello, &answered);
    ASSERT_TRUE(answered);
    ASSERT_TRUE(s->stream->Write(Step(1)));
    s->context.TryCancel();
    v1::ControlResponse r;
    while (s->stream->Read(&r)) {
    }
    EXPECT_EQ(s->stream->Finish().error_code(), G::CANCELLED);
    ExpectSessionsBecome(sessions);
    ExpectServerUnharmed();
  }
  CountCases("Control: ended mid-way", 2);
}

}  // namespace
}  // namespace nupmpc::testing
