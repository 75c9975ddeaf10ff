#include "cli/help_text.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "cli/own_flags.h"

namespace nupmpc::cli {
namespace {

constexpr int kWidth = 100;

// The default (and, if the program set it from the environment before parsing, the value
// in effect), strings quoted so that an empty default is visible.
std::string DefaultNote(const absl::CommandLineFlag& flag) {
  const bool quoted = flag.IsOfType<std::string>();
  const auto show = [quoted](const std::string& v) { return quoted ? absl::StrCat("\"", v, "\"") : v; };
  std::string note = absl::StrCat("(default ", show(flag.DefaultValue()));
  // Our programs set a flag before parsing only from an environment variable.
  if (flag.CurrentValue() != flag.DefaultValue())
    absl::StrAppend(&note, "; from the environment ", show(flag.CurrentValue()));
  return absl::StrCat(note, ")");
}

}  // namespace

std::string WrapText(absl::string_view text, int indent, int width) {
  std::string out;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    // A line that fits keeps its spacing (aligned columns in a summary); a long one wraps
    // at spaces, its continuation lines under its own first word.
    const std::size_t lead = std::min(line.find_first_not_of(' '), line.size());
    if (lead == line.size()) {  // blank
      out += "\n";
      continue;
    }
    if (static_cast<int>(indent + line.size()) <= width) {
      absl::StrAppend(&out, std::string(indent, ' '), line, "\n");
      continue;
    }
    const std::string prefix(indent + lead, ' ');
    std::string current = prefix;
    bool empty = true;
    for (absl::string_view word : absl::StrSplit(line.substr(lead), ' ', absl::SkipEmpty())) {
      if (!empty && static_cast<int>(current.size() + 1 + word.size()) > width) {
        absl::StrAppend(&out, current, "\n");
        current = prefix;
        empty = true;
      }
      absl::StrAppend(&current, empty ? "" : " ", word);
      empty = false;
    }
    absl::StrAppend(&out, current, "\n");
  }
  return out;
}

std::string HelpText(const ProgramInfo& program) {
  std::string out = WrapText(program.summary, 0, kWidth);
  absl::StrAppend(&out, "\nUsage: ", program.usage, "\n\nFlags:\n");
  for (const absl::CommandLineFlag* flag : OwnFlags()) {
    absl::StrAppend(&out, "  --", flag->Name(), "=<", FlagTypeName(*flag), ">  ", DefaultNote(*flag), "\n",
                    WrapText(flag->Help(), 6, kWidth));
  }
  absl::StrAppend(&out, "  -h, --help\n", WrapText("print this help and exit", 6, kWidth));
  if (!program.environment.empty()) {
    absl::StrAppend(&out, "\nEnvironment:\n");
    std::size_t name_width = 0;
    for (const EnvironmentVariable& v : program.environment) name_width = std::max(name_width, v.name.size());
    for (const EnvironmentVariable& v : program.environment) {
      const std::string head = absl::StrCat("  ", v.name, std::string(name_width - v.name.size() + 2, ' '));
      // The meaning wraps under itself, not under the variable's name.
      const std::string body = WrapText(v.meaning, static_cast<int>(head.size()), kWidth);
      absl::StrAppend(&out, head, body.size() > head.size() ? body.substr(head.size()) : "\n");
    }
  }
  return out;
}

}  // namespace nupmpc::cli
