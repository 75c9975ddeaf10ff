#ifndef NUPMPC_LOADTEST_INSTANCES_SESSION_KINDS_H_
#define NUPMPC_LOADTEST_INSTANCES_SESSION_KINDS_H_

// One instance as the session kinds the service builds differently (server/sessions/
// session_factory.cc): as it is (convex), with move suppression on the input differences
// (a quadratic penalty on Δu, so the input map augments the model), with a soft keep-out region in the plane of its
// first two outputs, and with binary inputs (at most 300 passes a solve: a non-convex search that would otherwise run
// to the default cap). For the tests and tools that must cover every kind (snapshots, hand-over).

#include <string>
#include <vector>

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::bench {

struct SessionKind {
  std::string name;  ///< "convex", "input differences", "keep-out", "binary inputs"
  v1::ProblemSpec spec;
};

// `base` needs at least two outputs (the keep-out plane) and input bounds (the binary
// levels are its first bounds).
std::vector<SessionKind> SessionKindsOf(const v1::ProblemSpec& base);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_INSTANCES_SESSION_KINDS_H_
