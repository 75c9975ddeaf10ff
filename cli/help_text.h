#ifndef NUPMPC_CLI_HELP_TEXT_H_
#define NUPMPC_CLI_HELP_TEXT_H_

// The text --help prints: what the program does, its usage line, its own flags (type,
// default, help) and the environment variables it reads.

#include <string>

#include "absl/strings/string_view.h"
#include "cli/program_info.h"

namespace nupmpc::cli {

// `text` indented by `indent`, lines longer than `width` wrapped at spaces (continuation
// lines as indented as the line's first word). Explicit newlines start new lines; lines
// that fit, and blank lines, are kept as they are.
std::string WrapText(absl::string_view text, int indent, int width);

std::string HelpText(const ProgramInfo& program);

}  // namespace nupmpc::cli

#endif  // NUPMPC_CLI_HELP_TEXT_H_
