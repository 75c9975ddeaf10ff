#include "client/solve_status_name.h"

#include "absl/strings/ascii.h"
#include "absl/strings/strip.h"

namespace nupmpc {

std::string SolveStatusName(v1::SolveStatus status) {
  return absl::AsciiStrToLower(absl::StripPrefix(v1::SolveStatus_Name(status), "SOLVE_STATUS_"));
}

}  // namespace nupmpc
