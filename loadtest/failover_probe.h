#ifndef NUPMPC_LOADTEST_FAILOVER_PROBE_H_
#define NUPMPC_LOADTEST_FAILOVER_PROBE_H_

// What deploy/scaleout-test.sh asks of several replicas behind a balancer, measured through
// the client library as a controller would use it (nupmpc::Session, AddressedSession):
//  * streams: C Control streams step through an instance's closed-loop states for a
//    while; replicas may die or drain meanwhile. Per stream: steps answered, steps failed
//    (returned to the caller as errors) and sessions re-created; and a sample of plans
//    checked against the core solving the same state from scratch. Streams take the
//    workload's session kinds in turn, and each keeps a never-moved twin in this process
//    (loadtest/twin_session.h): every answered plan is compared with the twin's, so a
//    session moved by a drain must continue exactly as if it had stayed.
//  * addressed: S sessions created with client-drawn ids and each solved R times by id:
//    every call must reach its session (no re-creation, each session counts R solves).

#include <atomic>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/channel_security.h"
#include "loadtest/instances/session_kinds.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::loadtest {

struct ProbeWorkload {
  std::string target;
  ChannelSecurity security;                 ///< TLS, client certificate, bearer token; none by default
  v1::ProblemSpec spec;                     ///< the addressed probe's sessions
  std::vector<std::vector<double>> states;  ///< cycled through
  std::vector<bench::SessionKind> kinds;    ///< streams probe: stream i is of kind i mod size (empty: spec, "convex")
};

struct StreamsProbeConfig {
  int streams = 24;
  double duration_s = 20.0;  ///< the longest the streams step
  /// When it becomes true, every stream ends after its current step (a script that ends
  /// the probe when its scenario is done, however slow the machine); null: duration_s only.
  const std::atomic<bool>* stop = nullptr;
  // Every k-th answered convex step is checked against the core (0: none), and every resent one.
  int verify_every = 25;
};

// The first answered step after a stream got its session back.
struct FirstStepAfterMove {
  std::string kind;
  bool reattached = false;   ///< by its id (restored from a snapshot); false: re-created cold
  unsigned passes = 0;       ///< the server's
  unsigned twin_passes = 0;  ///< the never-moved twin's (a re-created session's twin is re-created too)
  unsigned cold_passes = 0;  ///< what a cold re-create takes for the same state
  bool same_as_twin = false;
  bool cold_same_as_twin = false;  ///< would a cold re-create have given the twin's plan (a non-convex one may not)
  double cold_difference = 0.0;    ///< max |u - u_twin| of a cold re-create's plan
};

struct StreamsProbeReport {
  int streams = 0;
  std::uint64_t steps = 0;                      ///< answered with a result
  std::uint64_t failed_steps = 0;               ///< returned as errors
  std::uint64_t no_plan = 0;                    ///< results without a plan
  std::map<std::string, std::uint64_t> errors;  ///< by code name
  int affected_streams = 0;                     ///< streams that re-created their session or had a failed step
  std::uint64_t max_failed_per_affected = 0;
  int reconnects = 0;  ///< sessions got back after a broken stream, over all streams
  int reattached = 0;  ///< of them, attached again by their id (warm start kept)
  int recreated = 0;   ///< of them, re-created from the spec (cold)
  double longest_outage_s = 0.0;
  std::uint64_t verified = 0;    ///< plans compared with the core
  std::uint64_t mismatched = 0;  ///< of those, differing by more than 1e-9 (relative)
  double max_plan_difference = 0.0;
  std::uint64_t twin_compared = 0;    ///< answered steps compared with the stream's twin
  std::uint64_t twin_mismatched = 0;  ///< of those, a different plan or pass count
  std::vector<FirstStepAfterMove> first_steps;
  double solves_per_s = 0.0;
  double p50_ms = 0.0, p99_ms = 0.0;  ///< round trip of answered steps
};

absl::StatusOr<StreamsProbeReport> RunStreamsProbe(const ProbeWorkload& work, const StreamsProbeConfig& config);

struct AddressedProbeReport {
  int sessions = 0;
  std::uint64_t solves = 0;  ///< answered
  std::uint64_t failed = 0;  ///< returned as errors
  std::map<std::string, std::uint64_t> errors;
  int reattached = 0;  ///< sessions a failed call got back by their id (warm)
  int recreated = 0;   ///< sessions re-created (a call missed its session)
  int miscounted = 0;  ///< sessions whose server-side solve count is not R
};

absl::StatusOr<AddressedProbeReport> RunAddressedProbe(const ProbeWorkload& work, int sessions, int solves_each);

// The reports as one-line JSON objects.
std::string ToJson(const StreamsProbeReport& report);
std::string ToJson(const AddressedProbeReport& report);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_FAILOVER_PROBE_H_
