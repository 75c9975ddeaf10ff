#ifndef NUPMPC_LOADTEST_LOAD_STREAM_H_
#define NUPMPC_LOADTEST_LOAD_STREAM_H_

// One simulated controller of nupmpc-loadtest: a Control stream (gRPC callback API, so
// 64 streams need no 64 threads) that creates its session, then sends one measured state
// per request, cycling through the instance's closed-loop states (and, optionally, new
// output references).
//
// Closed loop: the next state goes out when the previous answer arrives.
// Open loop:   the load generator calls Send() at Poisson arrival times whether or not
//              answers came back; latency counts from the scheduled arrival, so a slow
//              server cannot hide queueing (no coordinated omission).

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc::loadtest {

namespace v1 = ::nupmpc::v1;
using Clock = std::chrono::steady_clock;

// What one stream observed during the measured window.
struct StreamTally {
  std::vector<double> latency_ms;  ///< answered solves, send (or scheduled arrival) → answer
  // The same from the moment the request was handed to gRPC: differs from latency_ms when
  // an open-loop generator falls behind its schedule (then the generator, not the server,
  // is the bottleneck).
  std::vector<double> service_ms;
  std::vector<double> solve_ms;  ///< the server's solver time of the same solves
  std::uint64_t iterations = 0;  ///< summed over answered solves
  std::uint64_t sent = 0;
  std::uint64_t superseded = 0;
  // Answers without SolveResult.has_plan (superseded ones aside): a controller holds its
  // last input through them. Counted in latency_ms like the others; the load test applies
  // no input at all (its states are recorded), so nothing is ever applied from them.
  std::uint64_t no_plan = 0;
  std::map<std::string, std::uint64_t> errors;  ///< canonical code name → count

  void MergeFrom(const StreamTally& other);
};

// StreamPlan.new_references: every output's prior as the spec has it, with one target for
// the whole horizon that moves with the step's sequence number (a slow sinusoid, amplitude
// 0.5, a different phase per output). Nothing for a spec without output priors (GP).
v1::PriorUpdate MovingReferences(const v1::ProblemSpec& spec, std::uint64_t sequence);

struct StreamPlan {
  const v1::ProblemSpec* spec = nullptr;
  const std::vector<std::vector<double>>* states = nullptr;  ///< cycled through
  bool closed_loop = true;
  // Every step also moves each output's reference (MovingReferences), as a tracking
  // controller does: each step is a changed problem, not only a changed state.
  bool new_references = false;
};

class LoadStream : public grpc::ClientBidiReactor<v1::ControlRequest, v1::ControlResponse> {
 public:
  LoadStream(v1::MpcService::Stub* stub, StreamPlan plan);

  // Opens the stream and creates the session; blocks until the server confirmed it.
  grpc::Status Open();
  // Requests scheduled in [from, until) are counted (earlier ones are warm-up); closed
  // loop sends its first state now.
  void BeginMeasuring(Clock::time_point from, Clock::time_point until);
  // Open loop: one arrival scheduled at `arrival`.
  void Send(Clock::time_point arrival);
  // No new requests; waits for outstanding answers (at most `drain`), ends the stream,
  // waits for it to finish.
  void Stop(std::chrono::milliseconds drain);
  std::uint64_t answered() const;
  StreamTally TakeTally();

  void OnWriteDone(bool ok) override;
  void OnReadDone(bool ok) override;
  void OnDone(const grpc::Status& status) override;

 private:
  void SendLocked(Clock::time_point scheduled);
  void StartNextWriteLocked();
  void RecordLocked(const v1::ControlResponse& response, Clock::time_point now);

  StreamPlan plan_;
  grpc::ClientContext context_;

  mutable std::mutex mu_;
  std::condition_variable changed_;
  v1::ControlResponse incoming_;
  std::deque<v1::ControlRequest> write_queue_;
  bool writing_ = false;
  bool writes_done_sent_ = false;
  bool session_ready_ = false;
  bool stopping_ = false;
  bool done_ = false;
  grpc::Status final_status_;
  std::uint64_t next_sequence_ = 1;
  std::size_t next_state_ = 0;
  Clock::time_point measure_from_ = Clock::time_point::max();
  Clock::time_point measure_until_ = Clock::time_point::max();
  bool Counted(Clock::time_point scheduled) const { return scheduled >= measure_from_ && scheduled < measure_until_; }
  struct Outstanding {
    Clock::time_point scheduled, sent;
  };
  std::unordered_map<std::uint64_t, Outstanding> outstanding_;  ///< by sequence
  std::uint64_t answered_ = 0;
  StreamTally tally_;
};

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_LOAD_STREAM_H_
