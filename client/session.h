#ifndef NUPMPC_CLIENT_SESSION_H_
#define NUPMPC_CLIENT_SESSION_H_

// nupmpc::Session: a session on a Control stream, opened by Client::OpenSession (client.h).
//
// Without a control period a step waits for its answer, and a broken stream is ridden
// through within the reconnect budget (client/reconnect.h): Step() returns the step's
// result or, once the budget is spent, UNAVAILABLE.
//
// With a control period P (ControlPeriod) a step returns by P after it was called, whatever
// the network does: with its result if the answer came, else HELD (SOLVE_STATUS_HELD, no
// plan: the caller holds its last input or applies its fallback). The answer of a held step,
// should it come later, is never returned for a later step (answers are matched by sequence
// number); it only keeps the session's spec current. The stream counts as broken when it
// ends, and also after K held periods in a row in which no answer at all came (a
// balancer's connection to a dead replica answers the client's keepalive pings, so only
// the missing answers tell; a live server slower than the period keeps its stream):
//
//   K = held_periods_to_reconnect, default max(3, ceil(1 s / P)),
//
// and then a background thread gets the session back (by its id, else re-created from its
// spec: ReattachOrRecreate, client/reconnect.h), for as long as the caller keeps stepping:
// no overall budget, back-off as in ReconnectOptions but at most 500 ms, each attempt
// cancelled after at most 1 s. Steps meanwhile return HELD at their
// period. The slack: a step returns within P plus the time to wake its thread and copy the
// result (well under a millisecond on an idle machine; tests allow 100 ms and more).
//
// Whether a held step's update (references, bounds, model) reached the server is unknown
// when its answer never comes; as for a SUPERSEDED step, a caller whose updates must not be
// lost repeats them in its next step.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "absl/status/statusor.h"
#include "client/control_call.h"
#include "client/reconnect.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc {

class Client;

struct ControlPeriod {
  // 0: none (a step waits for its answer). Finer than a millisecond, so that a period
  // such as 7.35 ms is kept as the client paces it, not truncated on its way to the server.
  std::chrono::microseconds period{0};
  int held_periods_to_reconnect = 0;  // K; 0: max(3, ceil(1 s / period))

  // The K in force, and the caps a period puts on the reconnect options.
  int HeldPeriodsToReconnect() const;
  static constexpr std::chrono::milliseconds kMaxBackoff{500};
  static constexpr std::chrono::milliseconds kMaxAttemptTimeout{1000};
};

class Session {
 public:
  using Clock = ControlCall::Clock;

  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  // One control period (see the top of this file).
  absl::StatusOr<v1::SolveResult> Step(const v1::Step& step);
  // The same on a separate thread; steps of one session still run one at a time.
  std::future<absl::StatusOr<v1::SolveResult>> StepAsync(v1::Step step);
  // Ends the stream (the server closes the session); later steps fail with
  // FAILED_PRECONDITION. With a period, returns OK within about two seconds (a reconnect
  // attempt in flight ends first, then the server's goodbye is awaited for a second).
  absl::Status Close();
  std::string id() const;
  int reconnects() const;
  // Reconnects, attempts, and how the session came back: re-attached (by its id, warm) or
  // re-created (from the spec, cold).
  ReconnectStats reconnect_stats() const;
  // Steps returned HELD, in all and in a row now.
  int held_steps() const;
  int consecutive_held_steps() const;
  // Answers that came after their step had returned HELD (discarded).
  int late_answers() const;

 private:
  friend class Client;
  Session(Client* client, v1::ProblemSpec spec, ReconnectOptions reconnect, ControlPeriod period);

  // A Control call on `channel` attached to a session: to `old_id` if not empty (the
  // session kept its warm start), else, or when the server no longer has it, to one
  // created from `spec` (ReattachOrRecreate, client/reconnect.h). Waits until `deadline`
  // at most; sets *id and `report`'s path. Not under mu_ (no member is used).
  static absl::StatusOr<std::shared_ptr<ControlCall>> Attach(const std::shared_ptr<grpc::Channel>& channel,
                                                             const std::string& old_id, const v1::ProblemSpec& spec,
                                                             std::uint64_t sequence, Clock::time_point deadline,
                                                             std::string* id, ReconnectAttempt* report);
  // Attach on the current channel (to id_, if any) and make it the session's call.
  absl::Status ConnectLocked(std::chrono::milliseconds timeout, ReconnectAttempt* report);
  // A channel of its own for the next attempt (see Step in session.cc). Under mu_.
  void RenewChannelLocked();
  // Sends `step` on the current call and waits for its answer until `deadline`: the
  // result, nullopt (held), or the step's or the stream's error.
  absl::StatusOr<std::optional<v1::SolveResult>> Exchange(const v1::Step& step,
                                                          ControlCall::Clock::time_point deadline);
  // An answer to an earlier step: applied to the spec, never returned.
  void TakeLateAnswer(const v1::ControlResponse& response);
  absl::StatusOr<v1::SolveResult> StepWaiting(const v1::Step& step);
  absl::StatusOr<v1::SolveResult> StepInPeriod(const v1::Step& step);
  // Drops the current call (if it is still `call`) and wakes the reconnect thread. Under mu_.
  void BreakLocked(const std::shared_ptr<ControlCall>& call, const absl::Status& cause);
  void ReconnectLoop();

  Client* client_;
  const ReconnectOptions reconnect_;
  const ControlPeriod period_;
  std::mutex step_mu_;  // one step (or Close) at a time

  mutable std::mutex mu_;  // everything below
  std::condition_variable changed_;
  // The client's channel, until a reconnect replaces it with one of the session's own.
  std::shared_ptr<grpc::Channel> channel_;
  std::shared_ptr<ControlCall> call_;             // null while the stream is broken
  v1::ProblemSpec spec_;                          // kept current with every answered step, for reconnects
  std::map<std::uint64_t, v1::Step> unanswered_;  // sent steps whose answer has not come
  std::string id_;
  std::uint64_t next_sequence_ = 1;
  ReconnectStats stats_;
  int held_steps_ = 0, consecutive_held_ = 0, late_answers_ = 0;
  int unreported_held_ = 0;  // held steps not yet told the server (ControlRequest.held_periods)
  int silent_periods_ = 0;   // held periods in a row in which no answer at all came (the K rule)
  // With a period: the reconnect thread's inputs.
  absl::Status break_cause_;
  ControlCall::Clock::time_point broken_at_{}, last_step_at_{};
  bool closing_ = false;
  std::thread reconnector_;
};

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_SESSION_H_
