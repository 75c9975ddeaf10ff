#ifndef NUPMPC_SERVER_SERVER_FLAGS_H_
#define NUPMPC_SERVER_SERVER_FLAGS_H_

#include <string>

#include "absl/status/statusor.h"
#include "cli/program_info.h"
#include "server/state/server_options.h"

namespace nupmpc::server {

// Parses the command line (absl flags). A flag not given on the command line falls back to
// the environment variable NUPMPC_<FLAG IN UPPER CASE> (e.g. NUPMPC_ADDRESS), then to its
// default. Returns the options and what main does with the process: the log level and
// how long SIGTERM reports NOT_SERVING before it drains.
struct ParsedFlags {
  ServerOptions options;
  std::string log_level;
  std::string log_format;  ///< text or json
  double drain_delay_s = 0.0;
};
// --help and unknown flags exit here (cli/program_flags.h); a value out of range or a bad
// environment variable is an error status.
absl::StatusOr<ParsedFlags> ParseServerFlags(int argc, char** argv);

// The server's --help and usage-error identity.
const cli::ProgramInfo& ServerProgram();

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SERVER_FLAGS_H_
