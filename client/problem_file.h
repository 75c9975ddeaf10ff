#ifndef NUPMPC_CLIENT_PROBLEM_FILE_H_
#define NUPMPC_CLIENT_PROBLEM_FILE_H_

// Reads the problem files the command-line tools accept: an instance in the
// benchmarks/ format (recognised by its "dims" key) or a ProblemSpec in proto
// JSON. Proto only: an instance becomes a v1::ProblemSpec directly (the one reader of the
// instance format; the core view of an instance, loadtest/instances/, is this spec through
// the server's conversion).

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "google/protobuf/util/json_util.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

struct ProblemFile {
  std::string name;  ///< an instance's "name" and "family" (empty for a ProblemSpec file)
  std::string family;
  v1::ProblemSpec spec;
  // The instance's recorded closed-loop initial states x1, one per step (empty when the
  // file has none, e.g. every ProblemSpec file).
  std::vector<std::vector<double>> closed_loop_states;
};

absl::StatusOr<ProblemFile> LoadProblemFile(const std::string& path);
// The same from the file's text (`name` prefixes the errors).
absl::StatusOr<ProblemFile> ParseProblemFile(const std::string& name, const std::string& text);

// An instance in the benchmarks/ format as a ProblemSpec: benchmark x_1 = x[0],
// y_n = y[n-1] (no output prior at step N); R and Qy must be diagonal (the priors are per
// scalar); per-step arrays that are constant are written as one value. INVALID_ARGUMENT
// naming the file and the field for a malformed instance.
absl::StatusOr<ProblemFile> LoadBenchmarkInstanceSpec(const std::string& path);

// The file's text (NOT_FOUND when it cannot be read).
absl::StatusOr<std::string> ReadTextFile(const std::string& path);

// A proto message in proto JSON (e.g. a FitGpModelRequest); INVALID_ARGUMENT naming the file.
template <typename Message>
absl::StatusOr<Message> LoadJsonMessage(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  Message out;
  const auto status = google::protobuf::util::JsonStringToMessage(*text, &out);
  if (!status.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": not a ", Message::descriptor()->name(), ": ", status.ToString()));
  }
  return out;
}

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_PROBLEM_FILE_H_
