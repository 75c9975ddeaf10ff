#ifndef NUPMPC_CLIENT_CONTROL_CALL_H_
#define NUPMPC_CLIENT_CONTROL_CALL_H_

// One Control stream of a nupmpc::Session, on gRPC's callback API, so that a step can wait
// for its answer with a deadline and return without it (a control period that ended) while
// the call goes on: a blocking Read could not be abandoned, and a blocking Write stalls for
// as long as the network does.
//
// Responses are read as they come and kept for WaitFor; requests go out one write at a
// time, and a request sent while a write is still in flight (the network stalls) replaces
// the one waiting behind it: the replaced request never reaches the server, which is what
// the server's own "newest state wins" would have done with it (proto ControlRequest).

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>

#include "absl/status/statusor.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc {

// The error a session reports for a Control call that ended with `status` before its
// answer: UNAVAILABLE (retryable: reconnect) for a stream that ended cleanly, was
// cancelled by the server or by gRPC for a dead connection, or ended without a status
// (a balancer whose replica died); the server's own error otherwise.
absl::Status BrokenControlStreamStatus(const grpc::Status& status);

class ControlCall : public grpc::ClientBidiReactor<v1::ControlRequest, v1::ControlResponse> {
 public:
  using Clock = std::chrono::steady_clock;

  // Starts a Control call on `channel` with `first` as its first message (the attach). The
  // call keeps the channel alive for as long as it lasts.
  ControlCall(std::shared_ptr<grpc::Channel> channel, const v1::ControlRequest& first);
  // Cancels the call if it is still open and waits until gRPC is done with it.
  ~ControlCall() override;
  ControlCall(const ControlCall&) = delete;
  ControlCall& operator=(const ControlCall&) = delete;

  // Sends `request` now, or after the write in flight; a request already waiting for that
  // write is dropped and its sequence returned (nothing of it reaches the server but its
  // held_periods, added to `request`'s).
  std::optional<std::uint64_t> Send(v1::ControlRequest request);

  // Waits until the response numbered `sequence` arrives (returned), `deadline` passes
  // (nullopt; time_point::max(): no deadline), or the call ends (BrokenControlStreamStatus). Every other response read
  // meanwhile (an answer that came too late for its own step) goes to `other` and is then dropped.
  absl::StatusOr<std::optional<v1::ControlResponse>> WaitFor(
      std::uint64_t sequence, Clock::time_point deadline, const std::function<void(const v1::ControlResponse&)>& other);

  // Half-closes the stream (after the write in flight) and waits for the call's status;
  // cancels the call at `deadline` (time_point::max(): never).
  grpc::Status Finish(Clock::time_point deadline);
  // Cancels the call (the server sees a cancellation) without waiting.
  void Cancel();
  // Whether the call has ended (its last response read; its status may follow).
  bool Ended() const;

 private:
  void OnWriteDone(bool ok) override;
  void OnReadDone(bool ok) override;
  void OnWritesDoneDone(bool ok) override;
  void OnDone(const grpc::Status& status) override;
  // Starts the waiting write, or the half-close, when no write is in flight. Under mu_.
  void PumpWritesLocked();
  // From now on no operation starts: gives gRPC the hold back (once), so the call can
  // complete. Not under mu_.
  void ReleaseHold();

  // A reader that does not take its answers must not make the client's memory grow: the
  // server sends at most one response per request, so this bounds a backlog that nobody
  // waits for (the oldest go first).
  static constexpr std::size_t kMaxUnreadResponses = 64;

  // Waits on changed_ until `ready` or `deadline` (time_point::max(): no deadline, which
  // wait_until could overflow into the past).
  template <typename Ready>
  bool WaitUntil(std::unique_lock<std::mutex>& lock, Clock::time_point deadline, Ready ready) {
    if (deadline == Clock::time_point::max()) {
      changed_.wait(lock, ready);
      return true;
    }
    return changed_.wait_until(lock, deadline, ready);
  }

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::MpcService::Stub> stub_;
  grpc::ClientContext context_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  v1::ControlRequest writing_;                 // the write in flight (gRPC reads it until OnWriteDone)
  std::optional<v1::ControlRequest> waiting_;  // the next write, behind it
  bool write_in_flight_ = false;
  bool writes_done_wanted_ = false;
  bool writes_done_started_ = false;
  bool ops_closed_ = false;      // ReleaseHold ran: nothing may start any more
  bool release_hold_ = false;    // the half-close started: ReleaseHold is due (outside mu_)
  bool read_failed_ = false;     // the stream is over (OnDone may still be pending)
  v1::ControlResponse reading_;  // the read in flight
  std::deque<v1::ControlResponse> responses_;
  bool done_ = false;
  grpc::Status status_;
};

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_CONTROL_CALL_H_
