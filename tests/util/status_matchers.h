#ifndef NUPMPC_TESTS_UTIL_STATUS_MATCHERS_H_
#define NUPMPC_TESTS_UTIL_STATUS_MATCHERS_H_

// StatusIs / IsOk matchers after absl/status/status_matchers.h (not in Abseil 20220623).

#include <ostream>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "gmock/gmock.h"

namespace nupmpc::testing {

inline const absl::Status& GetStatus(const absl::Status& s) { return s; }
template <typename T>
const absl::Status& GetStatus(const absl::StatusOr<T>& s) {
  return s.status();
}

MATCHER(IsOk, "is OK") {
  const absl::Status& s = GetStatus(arg);
  *result_listener << "status is " << s.ToString();
  return s.ok();
}

MATCHER_P2(StatusIs, code, message_matcher, "") {
  const absl::Status& s = GetStatus(arg);
  *result_listener << "status is " << s.ToString();
  return s.code() == code && ::testing::ExplainMatchResult(message_matcher, std::string(s.message()), result_listener);
}

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_STATUS_MATCHERS_H_
