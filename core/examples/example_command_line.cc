#include "core/examples/example_command_line.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "absl/flags/flag.h"
#include "cli/program_flags.h"

ABSL_FLAG(std::string, out_dir, "figures", "directory for the CSV files (created if missing)");

namespace nupmpc::examples {

std::string ParseExampleCommandLine(const cli::ProgramInfo& program, int argc, char** argv,
                                    const std::function<std::string()>& check) {
  cli::ParseProgramFlags(program, argc, argv);
  if (check) {
    if (const std::string problem = check(); !problem.empty()) std::exit(cli::ReportUsageError(program, problem));
  }
  const std::string dir = absl::GetFlag(FLAGS_out_dir);
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error) {
    std::fprintf(stderr, "%s: cannot create --out_dir %s: %s\n", program.name.c_str(), dir.c_str(),
                 error.message().c_str());
    std::exit(1);
  }
  return dir;
}

}  // namespace nupmpc::examples
