#ifndef NUPMPC_LOADTEST_TWIN_SESSION_H_
#define NUPMPC_LOADTEST_TWIN_SESSION_H_

// A Control stream's never-moved twin: an in-process session built and stepped by the
// server's own code (server::BuildSession, server::SolveStep) and fed exactly the states
// whose answers the stream received. A session that moved between replicas (a snapshot
// restored elsewhere) must keep giving the twin's plans, bit for bit and with the twin's
// pass count; that is what "bumpless" means for a controller.

#include <memory>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {
struct SessionEntry;
}

namespace nupmpc::loadtest {

class TwinSession {
 public:
  // Built from `spec` as the server builds a Control stream's session (no size limits: the
  // server has already admitted the same spec).
  static absl::StatusOr<TwinSession> Create(const v1::ProblemSpec& spec);

  // One control period, as the server solves it (no deadline: the twin's pass count must
  // not depend on this process's load).
  absl::StatusOr<v1::SolveResult> Step(const v1::Step& step);

 private:
  explicit TwinSession(std::shared_ptr<server::SessionEntry> entry) : entry_(std::move(entry)) {}
  std::shared_ptr<server::SessionEntry> entry_;
};

// The equality a moved session is held to: the same plan (inputs compared bit for bit, so
// that -0.0 and 0.0 or two NaNs are not waved through) after the same number of passes.
bool SamePlan(const v1::SolveResult& a, const v1::SolveResult& b);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_TWIN_SESSION_H_
