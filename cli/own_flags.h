#ifndef NUPMPC_CLI_OWN_FLAGS_H_
#define NUPMPC_CLI_OWN_FLAGS_H_

// The flags a program defines itself, as opposed to the ones Abseil registers in every
// program that parses flags (--flagfile, --fromenv, --tryfromenv, --undefok): those are
// neither documented nor accepted by our programs.

#include <string>
#include <vector>

#include "absl/flags/commandlineflag.h"
#include "absl/strings/string_view.h"

namespace nupmpc::cli {

// True for a flag defined in Abseil's own sources (Debian's library records them as
// "./absl/flags/parse.cc").
bool IsAbseilFilename(absl::string_view filename);

// Every registered, non-retired flag outside Abseil, sorted by name.
std::vector<absl::CommandLineFlag*> OwnFlags();

// The flag of that name if it is one of OwnFlags(), else nullptr.
absl::CommandLineFlag* FindOwnFlag(absl::string_view name);

// "bool", "int", "double", "string", ... for the help text ("value" for other types).
std::string FlagTypeName(const absl::CommandLineFlag& flag);

// Whether the flag's parser accepts `value`, without setting the flag (which the
// CommandLineFlag interface cannot do: its dry run is private). True for a type not in
// FlagTypeName's list: absl::ParseCommandLine then judges it.
bool AcceptsValue(const absl::CommandLineFlag& flag, absl::string_view value);

}  // namespace nupmpc::cli

#endif  // NUPMPC_CLI_OWN_FLAGS_H_
