#ifndef NUPMPC_TESTS_UTIL_CORE_SESSION_H_
#define NUPMPC_TESTS_UTIL_CORE_SESSION_H_

#include <memory>

#include "Eigen/Core"
#include "core/session/session.h"
#include "gtest/gtest.h"

namespace nupmpc::testing {

// A core session of `problem` with the default options; null (and a test failure) if
// the problem is refused.
inline std::unique_ptr<core::Session> MakeSession(const core::Problem& problem) {
  absl::StatusOr<std::unique_ptr<core::Session>> session = core::Session::Create(problem);
  EXPECT_TRUE(session.ok()) << session.status();
  return session.ok() ? *std::move(session) : nullptr;
}

// What a test compares of one solve.
struct Plan {
  Eigen::MatrixXd inputs;
  double objective = 0.0;
  int iterations = 0;
};

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_CORE_SESSION_H_
