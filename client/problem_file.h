#ifndef NUPMPC_CLIENT_PROBLEM_FILE_H_
#define NUPMPC_CLIENT_PROBLEM_FILE_H_

// Reads the problem files the command-line tools accept: an instance in the
// ../shared/benchmarks format (recognised by its "dims" key) or a ProblemSpec in proto
// JSON.

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

struct ProblemFile {
  v1::ProblemSpec spec;
  // The instance's recorded closed-loop initial states x1, one per step (empty when the
  // file has none, e.g. every ProblemSpec file).
  std::vector<std::vector<double>> closed_loop_states;
};

absl::StatusOr<ProblemFile> LoadProblemFile(const std::string& path);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_PROBLEM_FILE_H_
