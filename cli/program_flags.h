#ifndef NUPMPC_CLI_PROGRAM_FLAGS_H_
#define NUPMPC_CLI_PROGRAM_FLAGS_H_

// The one way every nupmpc program reads its command line:
//   --help, -h, --helpfull   print HelpText (what it does, usage, its own flags with type,
//                            default and help, its environment variables) and exit 0;
//   a usage error            "PROGRAM: unknown flag --x (see PROGRAM --help)" (and maybe
//                            "PROGRAM: did you mean --y?") on stderr and exit 2;
//   otherwise                absl::ParseCommandLine, returning the arguments that are not
//                            flags, argv[0] first.

#include <string>
#include <vector>

#include "absl/strings/string_view.h"
#include "cli/argument_check.h"
#include "cli/program_info.h"

namespace nupmpc::cli {

// Exit status of a usage error (as for getopt-style tools; 1 is left for failures at run time).
inline constexpr int kUsageErrorExit = 2;

std::vector<char*> ParseProgramFlags(const ProgramInfo& program, int argc, char** argv);

// What a usage error prints: "PROGRAM: ERROR (see PROGRAM --help)\n", and the hint, if
// any, on a line of its own.
std::string UsageErrorText(const ProgramInfo& program, absl::string_view error, absl::string_view hint = "");

// Prints UsageErrorText to stderr and returns kUsageErrorExit, for the checks a program
// makes itself after parsing (a missing file argument, a value out of range).
int ReportUsageError(const ProgramInfo& program, absl::string_view error);

}  // namespace nupmpc::cli

#endif  // NUPMPC_CLI_PROGRAM_FLAGS_H_
