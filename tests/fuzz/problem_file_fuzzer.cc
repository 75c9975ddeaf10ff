// Fuzz target (d): the readers of the command-line tools' problem files: the benchmark
// instance format and ProblemSpec JSON (client/problem_file.h). Properties: no crash or
// sanitizer report; an error names the file.
#include <cstddef>
#include <cstdint>
#include <string>

#include "client/problem_file.h"
#include "tests/fuzz/fuzz_limits.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::ParseProblemFile("fuzz.json", text);
  if (!file.ok() && file.status().message().find("fuzz.json") == absl::string_view::npos) {
    nupmpc::fuzz::Violated("a reader error that does not name the file");
  }
  return 0;
}
