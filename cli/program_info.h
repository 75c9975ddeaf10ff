#ifndef NUPMPC_CLI_PROGRAM_INFO_H_
#define NUPMPC_CLI_PROGRAM_INFO_H_

// What a program says about itself in --help and in its usage errors. The flags are not
// listed here: --help reads them from the flag registry (own_flags.h), so a new ABSL_FLAG
// appears in the help without anyone remembering to document it twice.

#include <string>
#include <vector>

namespace nupmpc::cli {

struct EnvironmentVariable {
  std::string name;     // e.g. "NUPMPC_SERVER"
  std::string meaning;  // e.g. "server address when --server is not given"
};

// Every member has a default so that a program names only what it has in a designated
// initialiser (GCC's -Wmissing-field-initializers exempts members with defaults).
struct ProgramInfo {
  std::string name = {};     // e.g. "nupmpc-server": the prefix of every message
  std::string summary = {};  // what the program does (long lines are wrapped at 100 columns)
  std::string usage = {};    // e.g. "nupmpc-server [FLAGS]"
  std::vector<EnvironmentVariable> environment = {};
  // Arguments that are not flags (a command, files); -1: any number. More than this is a
  // usage error, so that a stale positional argument is not silently ignored.
  int max_arguments = -1;
};

}  // namespace nupmpc::cli

#endif  // NUPMPC_CLI_PROGRAM_INFO_H_
