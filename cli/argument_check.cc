#include "cli/argument_check.h"

#include <algorithm>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "cli/own_flags.h"

namespace nupmpc::cli {
namespace {

// Abseil's names for its usage flags, and the short form people type first.
bool IsHelpFlag(absl::string_view name) {
  return name == "help" || name == "h" || name == "helpfull" || name == "helpshort" || name == "helppackage";
}

// Edits (insert, delete, substitute, swap two neighbours) from a to b: the optimal string
// alignment distance, so that "--hepl" is one edit from "--help".
std::size_t EditDistance(absl::string_view a, absl::string_view b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.size()][b.size()];
}

// Why `value` would be refused by the parser, or "" if it is accepted: with the flag's
// type, so the user knows what to write instead.
std::string ValueError(const absl::CommandLineFlag& flag, absl::string_view value) {
  if (AcceptsValue(flag, value)) return "";
  return absl::StrCat("bad value \"", value, "\" for --", flag.Name(), " (expects ", FlagTypeName(flag), ")");
}

}  // namespace

std::string SuggestFlag(absl::string_view name) {
  // Abseil's flags are spelt with underscores; people often type dashes or capitals.
  std::string normalised = absl::AsciiStrToLower(absl::StrReplaceAll(name, {{"-", "_"}}));
  if (normalised.empty()) return "";
  if (normalised != name && FindOwnFlag(normalised) != nullptr) return normalised;
  std::vector<std::string> candidates = {"help"};
  for (const absl::CommandLineFlag* flag : OwnFlags()) candidates.emplace_back(flag->Name());
  // A unique prefix of a long name ("--conc" for "--concurrency").
  std::vector<std::string> prefixed;
  for (const std::string& c : candidates) {
    if (normalised.size() >= 3 && absl::StartsWith(c, normalised)) prefixed.push_back(c);
  }
  if (prefixed.size() == 1) return prefixed[0];
  // A typo: a few edits, fewer for short names (so "--x" does not suggest "--h...").
  const std::size_t allowed = 1 + normalised.size() / 5;
  std::string best;
  std::size_t best_distance = allowed + 1;
  for (const std::string& c : candidates) {
    if (const std::size_t d = EditDistance(normalised, c); d < best_distance) {
      best = c;
      best_distance = d;
    }
  }
  return best;
}

ArgumentCheck CheckArguments(const ProgramInfo& program, const std::vector<std::string>& args) {
  bool help = false;
  ArgumentCheck error;  // kParse until a problem is found
  const auto fail = [&error](std::string what, std::string hint = "") {
    // The first problem is reported; later ones are often its consequence.
    if (error.outcome == ArgumentCheck::Outcome::kParse)
      error = {ArgumentCheck::Outcome::kUsageError, std::move(what), std::move(hint)};
  };
  std::vector<absl::string_view> positional;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const absl::string_view arg = args[i];
    if (arg == "--") {  // everything after it is an argument, as for getopt
      positional.insert(positional.end(), args.begin() + i + 1, args.end());
      break;
    }
    if (arg.size() < 2 || arg[0] != '-') {  // "-" alone is an argument (stdin), as in Abseil
      positional.push_back(arg);
      continue;
    }
    // Abseil accepts -name as well as --name, and a value after "=" or as the next argument.
    const absl::string_view body = arg.substr(arg[1] == '-' ? 2 : 1);
    const std::size_t equals = body.find('=');
    const absl::string_view name = body.substr(0, equals);
    const bool has_value = equals != absl::string_view::npos;
    absl::string_view value = has_value ? body.substr(equals + 1) : absl::string_view();
    if (IsHelpFlag(name)) {
      help = true;
      continue;
    }
    absl::CommandLineFlag* flag = FindOwnFlag(name);
    bool negated = false;
    if (flag == nullptr && absl::StartsWith(name, "no")) {
      absl::CommandLineFlag* positive = FindOwnFlag(name.substr(2));
      if (positive != nullptr && positive->IsOfType<bool>()) {
        flag = positive;
        negated = true;
      } else if (positive != nullptr) {
        fail(absl::StrCat("--", name, ": only yes/no flags have a --no form; --", positive->Name(), " expects ",
                          FlagTypeName(*positive)));
        continue;
      }
    }
    if (flag == nullptr) {
      const std::string suggestion = SuggestFlag(name);
      fail(absl::StrCat("unknown flag --", name),
           suggestion.empty() ? "" : absl::StrCat("did you mean --", suggestion, "?"));
      continue;
    }
    if (flag->IsOfType<bool>()) {
      // --flag, --noflag, --flag=true|false; a bool never takes the next argument.
      if (negated && has_value) {
        fail(absl::StrCat("--", name, " takes no value"));
      } else if (has_value) {
        if (std::string problem = ValueError(*flag, value); !problem.empty()) fail(std::move(problem));
      }
      continue;
    }
    if (!has_value) {
      if (i + 1 == args.size()) {
        fail(absl::StrCat("flag --", name, " needs a value (", FlagTypeName(*flag), ")"));
        continue;
      }
      value = args[++i];
    }
    if (std::string problem = ValueError(*flag, value); !problem.empty()) fail(std::move(problem));
  }
  // Help wins over everything else: someone who asks for it mid-command gets it.
  if (help) return {ArgumentCheck::Outcome::kHelp, "", ""};
  if (error.outcome == ArgumentCheck::Outcome::kParse && program.max_arguments >= 0 &&
      positional.size() > static_cast<std::size_t>(program.max_arguments)) {
    fail(absl::StrCat("unexpected argument \"", positional[program.max_arguments], "\""));
  }
  return error;
}

}  // namespace nupmpc::cli
