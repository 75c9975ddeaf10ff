#ifndef NUPMPC_CLI_ARGUMENT_CHECK_H_
#define NUPMPC_CLI_ARGUMENT_CHECK_H_

// Reads a command line against the program's own flags before anything is set: asks for
// help, is a usage error (unknown flag, missing or malformed value, too many arguments),
// or can be handed to absl::ParseCommandLine. Abseil's own parser would print "No flags
// matched" for --help (Debian's 20220623 only lists flags of files named like the
// program) and exit 1 on an unknown flag without a hint; this check runs first so that
// neither reaches it.

#include <string>
#include <vector>

#include "absl/strings/string_view.h"
#include "cli/program_info.h"

namespace nupmpc::cli {

struct ArgumentCheck {
  enum class Outcome { kParse, kHelp, kUsageError };
  Outcome outcome = Outcome::kParse;
  std::string error;  // kUsageError: what is wrong, e.g. "unknown flag --frobnicate"
  std::string hint;   // kUsageError, optional: e.g. "did you mean --format?"
};

// `args` without the program name (argv[1..]).
ArgumentCheck CheckArguments(const ProgramInfo& program, const std::vector<std::string>& args);

// The own flag whose name is closest to `name` (a dash for an underscore, a typo, a
// prefix), or "" when none is close enough to be a plausible intent.
std::string SuggestFlag(absl::string_view name);

}  // namespace nupmpc::cli

#endif  // NUPMPC_CLI_ARGUMENT_CHECK_H_
