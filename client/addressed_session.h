#ifndef NUPMPC_CLIENT_ADDRESSED_SESSION_H_
#define NUPMPC_CLIENT_ADDRESSED_SESSION_H_

// A session driven by unary Solve calls addressed by its id: for controllers that do not
// hold a Control stream open, and behind a balancer with several replicas (the proto's
// comment above MpcService). Every call carries the id in the x-nupmpc-session header.
//
//   nupmpc::Client client("balancer:50051");
//   auto session = nupmpc::AddressedSession::Create(&client, spec);
//   auto result = (*session)->Step(step);        // Solve on the replica holding the session
//
// Failover, with the back-off of ReconnectOptions (client/reconnect.h): when a Solve fails
// with UNAVAILABLE (the replica or the connection is gone, or it drains), the step is
// resent to the same id first: a replica that kept the session, or restored it from the
// snapshot a drained or restarted one wrote (--state_dir), answers it warm (re-attached).
// When that answers NOT_FOUND, or the first Solve did (the balancer now sends the id to a
// replica that has neither the session nor its snapshot, or the session expired), the
// session is re-created from the spec it holds (kept current with every answered step by
// ApplyStepToSpec, as nupmpc::Session does) under a new id, on whichever replica answers,
// and the step is resent there (re-created, cold). Step() thus returns that step's own
// result, or an error: never a plan computed for another state. A new id rather than the
// old one, so that a replica that comes back with a stale copy is never reached again.
// After a step that failed (other than a refusal), the next step must carry its state: the
// server may have applied the failed one, so the spec held may lag behind it.
//
// Solve calls have the client's default deadline (none by default: a solve may take long);
// the calls of a failover attempt by ReconnectOptions.attempt_timeout, closes by 2 s.

#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "client/client.h"
#include "client/reconnect.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

class AddressedSession {
 public:
  // Creates the session (one attempt: a wrong address or spec fails at once).
  static absl::StatusOr<std::unique_ptr<AddressedSession>> Create(Client* client, v1::ProblemSpec spec,
                                                                  ReconnectOptions reconnect = {});
  ~AddressedSession();  // closes the session (best effort)

  // One control period (blocking), with failover as above.
  absl::StatusOr<v1::SolveResult> Step(const v1::Step& step);
  absl::Status Close();
  std::string id() const;
  ReconnectStats reconnect_stats() const;

 private:
  AddressedSession(Client* client, v1::ProblemSpec spec, ReconnectOptions reconnect)
      : client_(client), spec_(std::move(spec)), reconnect_(std::move(reconnect)) {}
  // CreateSession under a new id, bounded by `timeout`.
  absl::Status CreateLocked(std::chrono::milliseconds timeout);
  absl::StatusOr<v1::SolveResult> SolveLocked(const v1::Step& step, std::chrono::milliseconds timeout);
  // CloseSession on `id` with a short deadline (best effort where its result is ignored).
  absl::Status CloseById(const std::string& id);

  Client* client_;
  v1::ProblemSpec spec_;
  ReconnectOptions reconnect_;
  mutable std::mutex mu_;
  std::string id_;             // empty once closed
  bool spec_may_lag_ = false;  // a step failed unanswered since the last one with a state
  ReconnectStats stats_;
};

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_ADDRESSED_SESSION_H_
