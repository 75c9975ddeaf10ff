// The service's half of running several replicas behind one balancer: sessions under the
// id the client drew (so CreateSession can be routed like every later call), and the
// client's AddressedSession, which re-creates a lost session and answers every step for
// the state that step sent.
#include "client/session_routing.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "absl/strings/ascii.h"
#include "client/addressed_session.h"
#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

v1::Step StepFrom(const Eigen::VectorXd& x) {
  v1::Step step;
  step.mutable_state()->Add(x.data(), x.data() + x.size());
  return step;
}

TEST_F(ServiceTest, ASessionTakesTheIdItsClientDrew) {
  const v1::ProblemSpec spec = SpecOrDie(LoadInstanceOrDie("masses_N30").problem);
  const std::string id = NewSessionId();
  ASSERT_EQ(id.size(), 32u);
  auto created = client_->CreateSession(spec, id);
  ASSERT_TRUE(created.ok()) << created.status();
  EXPECT_EQ(created->session_id(), id);
  EXPECT_TRUE(client_->GetSession(id).ok());

  auto again = client_->CreateSession(spec, id);
  EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_NE(again.status().message().find("session_id"), std::string::npos) << again.status();
  for (const std::string& bad : {std::string("not-an-id"), absl::AsciiStrToUpper(NewSessionId())}) {
    auto malformed = client_->CreateSession(spec, bad);
    EXPECT_EQ(malformed.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(malformed.status().message().find("CreateSessionRequest.session_id"), std::string::npos)
        << malformed.status();
  }
  EXPECT_EQ(server_->state().registry.size(), 1);  // the refused calls created nothing

  // Without an id the client draws a fresh one each time.
  auto first = client_->CreateSession(spec);
  auto second = client_->CreateSession(spec);
  ASSERT_TRUE(first.ok() && second.ok());
  EXPECT_NE(first->session_id(), second->session_id());
}

// A replica that lost the session (here: it was closed behind the client's back, as a
// balancer's rehash or a restart would look) answers NOT_FOUND; the AddressedSession
// re-creates it under a new id and resends the step, whose plan is the optimum for the
// state it sent.
TEST_F(ServiceTest, AnAddressedSessionRecreatesALostSessionForTheStateItSent) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  const v1::ProblemSpec spec = SpecOrDie(inst.problem);
  const std::vector<Eigen::VectorXd>& states = inst.closed_loop->x1;
  ReconnectOptions fast;
  fast.initial_backoff = std::chrono::milliseconds(1);
  auto session = AddressedSession::Create(client_.get(), spec, fast);
  ASSERT_TRUE(session.ok()) << session.status();
  ASSERT_TRUE((*session)->Step(StepFrom(states[0])).ok());
  const std::string lost_id = (*session)->id();
  ASSERT_TRUE(client_->CloseSession(lost_id).ok());

  auto answered = (*session)->Step(StepFrom(states[1]));
  ASSERT_TRUE(answered.ok()) << answered.status();
  ASSERT_TRUE(HasPlan(*answered));
  EXPECT_EQ((*session)->reconnect_stats().reconnects, 1);
  EXPECT_EQ((*session)->reconnect_stats().recreated, 1);
  EXPECT_EQ((*session)->reconnect_stats().reattached, 0);
  EXPECT_NE((*session)->id(), lost_id);
  EXPECT_EQ(client_->GetSession(lost_id).status().code(), absl::StatusCode::kNotFound);

  // The same state solved from scratch: the plans agree to rounding.
  v1::ProblemSpec from_state = spec;
  *from_state.mutable_initial_state()->mutable_mean() = StepFrom(states[1]).state();
  auto reference = client_->SolveOnce(from_state);
  ASSERT_TRUE(reference.ok()) << reference.status();
  ASSERT_EQ(reference->inputs_size(), answered->inputs_size());
  double largest = 0.0, difference = 0.0;
  for (int i = 0; i < answered->inputs_size(); ++i) {
    largest = std::max(largest, std::abs(reference->inputs(i)));
    difference = std::max(difference, std::abs(answered->inputs(i) - reference->inputs(i)));
  }
  EXPECT_LE(difference, 1e-9 * std::max(1.0, largest));

  ASSERT_TRUE((*session)->Close().ok());
  EXPECT_EQ(server_->state().registry.size(), 0);
}

// Errors that re-creating cannot fix are returned at once, and the session stays.
TEST_F(ServiceTest, AnAddressedSessionReturnsABadStepsErrorWithoutRecreating) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  auto session = AddressedSession::Create(client_.get(), SpecOrDie(inst.problem));
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  v1::Step wrong_size;
  wrong_size.add_state(1.0);
  auto refused = (*session)->Step(wrong_size);
  EXPECT_FALSE(refused.ok());
  EXPECT_FALSE(IsRetryable(refused.status())) << refused.status();
  EXPECT_NE(refused.status().message().find("state"), std::string::npos) << refused.status();
  EXPECT_EQ((*session)->reconnect_stats().attempts, 0);
  EXPECT_EQ((*session)->id(), id);
}

}  // namespace
}  // namespace nupmpc::testing
