#ifndef NUPMPC_CORE_EXAMPLES_EXAMPLE_COMMAND_LINE_H_
#define NUPMPC_CORE_EXAMPLES_EXAMPLE_COMMAND_LINE_H_

// The command line of the nupmpc-example-* programs: --out_dir DIR (default "figures")
// and whatever flags the program defines itself, read through cli/program_flags.h (so
// --help and unknown flags exit before anything runs).

#include <functional>
#include <string>

#include "cli/program_info.h"

namespace nupmpc::examples {

// Parses the command line and returns --out_dir, created if missing (only now, so that
// --help or a usage error leaves no directory behind). `check` validates the program's
// own flags after parsing: a non-empty message is a usage error (exit 2). Exits 1 when
// the directory cannot be created.
std::string ParseExampleCommandLine(const cli::ProgramInfo& program, int argc, char** argv,
                                    const std::function<std::string()>& check = {});

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_EXAMPLE_COMMAND_LINE_H_
