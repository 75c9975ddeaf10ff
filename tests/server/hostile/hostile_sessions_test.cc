// The hostile-input catalogue's session classes: ids that name no usable
// session (unknown, closed, malformed, another principal's) on every call that takes one,
// and a session used across calls and streams (solved by id while a stream is attached,
// attached twice, closed while a stream uses it, a stream-owned session reached from
// elsewhere). Each case gets its code and a message naming session_id; the sessions in use
// answer as before, a healthy session answers with the bit-identical plan and resident
// memory has not jumped.
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/session_routing.h"
#include "gmock/gmock.h"
#include "tests/server/hostile/hostile_catalogue.h"

namespace nupmpc::testing {
namespace {

using C = absl::StatusCode;
using G = grpc::StatusCode;

v1::ControlRequest AttachTo(const std::string& id) {
  v1::ControlRequest r;
  r.set_session_id(id);
  return r;
}

// A refused attach by id: a miss (NOT_FOUND, FAILED_PRECONDITION) is answered in the stream
// too, naming no session, before the stream ends with it (a balancer may drop that status,
// and a reconnecting client must learn to re-create); a malformed id is not answered.
void ExpectRefusalAnswer(bool answered, const v1::ControlResponse& answer, G code) {
  const bool miss = code == G::NOT_FOUND || code == G::FAILED_PRECONDITION;
  EXPECT_EQ(answered, miss) << answer.ShortDebugString();
  if (!answered) return;
  EXPECT_EQ(answer.error_code(), static_cast<int>(code)) << answer.error_message();
  EXPECT_THAT(answer.error_message(), ::testing::HasSubstr("session_id"));
  EXPECT_TRUE(answer.session_id().empty());
}

class HostileSessionsTest : public HostileCatalogueTest {
 protected:
  // A Control stream attaching by `id` must end with `code` and name session_id.
  void ExpectAttachRefused(const std::string& id, G code) {
    v1::ControlResponse answer;
    bool answered = false;
    std::unique_ptr<OpenStream> s = OpenControl(AttachTo(id), &answer, &answered);
    ExpectRefusalAnswer(answered, answer, code);
    ExpectRefused(EndStream(s.get()), code, "session_id");
  }
  // One step on an open stream; the answer.
  v1::ControlResponse StreamStep(OpenStream* s, std::uint64_t sequence) {
    v1::ControlRequest r;
    r.set_sequence(sequence);
    *r.mutable_step() = StateStep(4);
    EXPECT_TRUE(s->stream->Write(r));
    v1::ControlResponse answer;
    EXPECT_TRUE(s->stream->Read(&answer));
    EXPECT_EQ(answer.sequence(), sequence);
    return answer;
  }
};

// Every call that names a session, with ids that name none it may use.
TEST_F(HostileSessionsTest, IdsThatNameNoUsableSessionOnEveryCallThatTakesOne) {
  auto closed = client_->CreateSession(spec_);
  ASSERT_TRUE(closed.ok()) << closed.status();
  ASSERT_TRUE(client_->CloseSession(closed->session_id()).ok());
  struct Id {
    const char* kind;
    std::string id;
    C code;
  };
  const Id ids[] = {
      {"unknown", NewSessionId(), C::kNotFound},
      {"closed", closed->session_id(), C::kNotFound},
      {"malformed", "not-a-session", C::kInvalidArgument},
      {"empty", "", C::kInvalidArgument},
      {"too long", std::string(100000, 'a'), C::kInvalidArgument},
  };
  struct Call {
    const char* rpc;
    std::function<absl::Status(const std::string&)> call;
  };
  const Call calls[] = {
      {"Solve", [&](const std::string& id) { return client_->Solve(id, StateStep(4)).status(); }},
      {"GetSession", [&](const std::string& id) { return client_->GetSession(id).status(); }},
      {"CloseSession", [&](const std::string& id) { return client_->CloseSession(id); }},
  };
  int cases = 0;
  for (const Id& id : ids) {
    for (const Call& call : calls) {
      SCOPED_TRACE(absl::StrCat(call.rpc, " with an id ", id.kind));
      ExpectRefused(call.call(id.id), id.code, "session_id");
      ExpectServerUnharmed();
      ++cases;
    }
    SCOPED_TRACE(absl::StrCat("Control attach with an id ", id.kind));
    ExpectAttachRefused(id.id, static_cast<G>(id.code));
    ExpectServerUnharmed();
    ++cases;
  }
  // A refused id is echoed by a short prefix only.
  const absl::Status long_id = client_->GetSession(std::string(100000, 'a')).status();
  EXPECT_LT(long_id.message().size(), 200u) << long_id;
  CountCases("session ids: unknown, closed, malformed", cases);
}

// With tokens: another principal's session answers exactly as an unknown one, and stays
// its owner's, unchanged.
TEST_F(HostileSessionsTest, AnotherPrincipalsSessionIsNotFoundOnEveryCallThatTakesAnId) {
  const std::string tokens = ::testing::TempDir() + "/hostile-tokens-" + std::to_string(::getpid());
  constexpr char kAlice[] = "alice-0123456789abcdef", kBob[] = "bob-0123456789abcdef01";
  std::ofstream(tokens) << kAlice << " alice\n" << kBob << " bob\n";
  server::ServerOptions options = DefaultOptions();
  options.auth_tokens_file = tokens;
  RestartServer(options, kAlice);
  ChannelSecurity as_bob;
  as_bob.token = kBob;
  absl::StatusOr<std::unique_ptr<Client>> bob = Client::Connect(target_, as_bob, std::chrono::seconds(30));
  ASSERT_TRUE(bob.ok()) << bob.status();
  const std::string id = healthy_id_;  // alice's

  const std::function<absl::Status()> calls[] = {
      [&] { return (*bob)->Solve(id, StateStep(4)).status(); },
      [&] { return (*bob)->GetSession(id).status(); },
      [&] { return (*bob)->CloseSession(id); },
      [&] {
        grpc::ClientContext context;
        auto stream = (*bob)->stub().Control(&context);
        v1::ControlRequest attach = AttachTo(id);
        *attach.mutable_step() = StateStep(4);
        EXPECT_TRUE(stream->Write(attach));
        stream->WritesDone();
        v1::ControlResponse answer;
        ExpectRefusalAnswer(stream->Read(&answer), answer, G::NOT_FOUND);  // as for an unknown id
        const grpc::Status s = stream->Finish();
        return absl::Status(static_cast<C>(s.error_code()), s.error_message());
      },
  };
  for (const auto& call : calls) {
    const absl::Status refused = call();
    ExpectRefused(refused, C::kNotFound, "session_id");
    EXPECT_THAT(std::string(refused.message()), ::testing::HasSubstr("no such session"));
    ExpectServerUnharmed();  // alice's session, solved by alice: the plan it gave before
  }
  EXPECT_EQ(server_->state().registry.size(), 1);
  std::filesystem::remove(tokens);
  CountCases("session ids: another principal's", static_cast<int>(std::size(calls)));
}

// A session reached from a second call or stream while a stream uses it.
TEST_F(HostileSessionsTest, ASessionUsedAcrossCallsAndStreams) {
  auto attached = client_->CreateSession(spec_);
  ASSERT_TRUE(attached.ok()) << attached.status();
  const std::string id = attached->session_id();
  v1::ControlResponse answer;
  bool answered = false;
  std::unique_ptr<OpenStream> a = OpenControl(AttachTo(id), &answer, &answered);
  ASSERT_TRUE(answered);
  EXPECT_EQ(answer.session_id(), id);
  v1::ControlRequest create;
  *create.mutable_spec() = spec_;
  std::unique_ptr<OpenStream> owner = OpenControl(create, &answer, &answered);
  ASSERT_TRUE(answered);
  const std::string owned = answer.session_id();
  ASSERT_EQ(owned.size(), 32u);

  struct Case {
    const char* what;
    std::function<absl::Status()> call;
    C code;
  };
  const auto attach = [&](const std::string& to) {
    return [this, to] {
      v1::ControlResponse a2;
      bool ok = false;
      std::unique_ptr<OpenStream> s = OpenControl(AttachTo(to), &a2, &ok);
      ExpectRefusalAnswer(ok, a2, G::FAILED_PRECONDITION);
      const grpc::Status st = EndStream(s.get());
      return absl::Status(static_cast<C>(st.error_code()), st.error_message());
    };
  };
  const Case cases[] = {
      {"Solve by id while a stream is attached", [&] { return client_->Solve(id, StateStep(4)).status(); },
       C::kFailedPrecondition},
      {"a second stream attaching", attach(id), C::kFailedPrecondition},
      {"Solve by id on a stream's own session", [&] { return client_->Solve(owned, StateStep(4)).status(); },
       C::kFailedPrecondition},
      {"CloseSession of a stream's own session", [&] { return client_->CloseSession(owned); }, C::kFailedPrecondition},
      {"attaching to a stream's own session", attach(owned), C::kFailedPrecondition},
      {"CreateSession under an id in use", [&] { return client_->CreateSession(spec_, id).status(); },
       C::kAlreadyExists},
  };
  std::uint64_t sequence = 1;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    ExpectRefused(c.call(), c.code, "session_id");
    // Both streams' sessions answer as before.
    for (OpenStream* s : {a.get(), owner.get()}) {
      const v1::ControlResponse r = StreamStep(s, sequence++);
      ASSERT_EQ(r.error_code(), 0) << r.error_message();
      ExpectHealthyPlan(r.result());
    }
    ExpectServerUnharmed();
  }
  // Closed by another call while the stream is attached: the next step says so, the
  // stream ends cleanly and the owner's stream goes on.
  ASSERT_TRUE(client_->CloseSession(id).ok());
  const v1::ControlResponse after_close = StreamStep(a.get(), sequence++);
  EXPECT_EQ(after_close.error_code(), static_cast<int>(G::NOT_FOUND)) << after_close.error_message();
  EXPECT_THAT(after_close.error_message(), ::testing::HasSubstr("session_id"));
  EXPECT_TRUE(EndStream(a.get()).ok());
  const v1::ControlResponse owner_after = StreamStep(owner.get(), sequence++);
  ASSERT_EQ(owner_after.error_code(), 0) << owner_after.error_message();
  ExpectHealthyPlan(owner_after.result());
  EXPECT_TRUE(EndStream(owner.get()).ok());
  ExpectServerUnharmed();

  // A stream that detached leaves the session usable by id again.
  auto again = client_->CreateSession(spec_);
  ASSERT_TRUE(again.ok());
  std::unique_ptr<OpenStream> once = OpenControl(AttachTo(again->session_id()), &answer, &answered);
  ASSERT_TRUE(answered);
  EXPECT_TRUE(EndStream(once.get()).ok());
  // The server detaches when the stream is done, which may lag the client's Finish.
  bool detached = false;
  for (int i = 0; i < 500 && !detached; ++i) {
    auto info = client_->GetSession(again->session_id());
    ASSERT_TRUE(info.ok()) << info.status();
    detached = !info->attached();
    if (!detached) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(detached);
  auto by_id = client_->Solve(again->session_id(), StateStep(4));
  ASSERT_TRUE(by_id.ok()) << by_id.status();
  ExpectHealthyPlan(*by_id);
  ExpectServerUnharmed();
  CountCases("sessions across calls and streams", static_cast<int>(std::size(cases)) + 2);
}

}  // namespace
}  // namespace nupmpc::testing
