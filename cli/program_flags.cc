#include "cli/program_flags.h"

#include <cstdio>
#include <cstdlib>

#include "absl/flags/parse.h"
#include "absl/strings/str_cat.h"
#include "cli/help_text.h"

namespace nupmpc::cli {

std::vector<char*> ParseProgramFlags(const ProgramInfo& program, int argc, char** argv) {
  const ArgumentCheck check = CheckArguments(program, std::vector<std::string>(argv + 1, argv + argc));
  switch (check.outcome) {
    case ArgumentCheck::Outcome::kHelp:
      std::fputs(HelpText(program).c_str(), stdout);
      std::exit(0);
    case ArgumentCheck::Outcome::kUsageError:
      std::fputs(UsageErrorText(program, check.error, check.hint).c_str(), stderr);
      std::exit(kUsageErrorExit);
    case ArgumentCheck::Outcome::kParse:
      break;
  }
  return absl::ParseCommandLine(argc, argv);
}

std::string UsageErrorText(const ProgramInfo& program, absl::string_view error, absl::string_view hint) {
  std::string text = absl::StrCat(program.name, ": ", error, " (see ", program.name, " --help)\n");
  if (!hint.empty()) absl::StrAppend(&text, program.name, ": ", hint, "\n");
  return text;
}

int ReportUsageError(const ProgramInfo& program, absl::string_view error) {
  std::fputs(UsageErrorText(program, error).c_str(), stderr);
  return kUsageErrorExit;
}

}  // namespace nupmpc::cli
