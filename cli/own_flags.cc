#include "cli/own_flags.h"

#include <algorithm>
#include <cstdint>

#include "absl/flags/marshalling.h"
#include "absl/flags/reflection.h"
#include "absl/strings/match.h"

namespace nupmpc::cli {

bool IsAbseilFilename(absl::string_view filename) {
  return absl::StartsWith(filename, "absl/") || absl::StrContains(filename, "/absl/");
}

std::vector<absl::CommandLineFlag*> OwnFlags() {
  std::vector<absl::CommandLineFlag*> flags;
  for (const auto& [name, flag] : absl::GetAllFlags()) {
    if (!flag->IsRetired() && !IsAbseilFilename(flag->Filename())) flags.push_back(flag);
  }
  std::sort(flags.begin(), flags.end(),
            [](const absl::CommandLineFlag* a, const absl::CommandLineFlag* b) { return a->Name() < b->Name(); });
  return flags;
}

absl::CommandLineFlag* FindOwnFlag(absl::string_view name) {
  absl::CommandLineFlag* flag = absl::FindCommandLineFlag(name);
  if (flag == nullptr || flag->IsRetired() || IsAbseilFilename(flag->Filename())) return nullptr;
  return flag;
}

namespace {

// One entry per supported type: its name in the help and a parse into a scratch value.
template <typename T>
bool Parses(absl::string_view value) {
  T scratch{};
  std::string error;
  return absl::ParseFlag(value, &scratch, &error);
}

struct FlagType {
  const char* name;
  bool (*is)(const absl::CommandLineFlag&);
  bool (*parses)(absl::string_view);
};

template <typename T>
constexpr FlagType Type(const char* name) {
  return {name, [](const absl::CommandLineFlag& f) { return f.IsOfType<T>(); }, &Parses<T>};
}

// CommandLineFlag has no public type name in Abseil 20220623; ask for the types our
// programs use.
constexpr FlagType kTypes[] = {
    Type<bool>("bool"),       Type<int32_t>("int"),        Type<int64_t>("int64"),
    Type<uint32_t>("uint32"), Type<uint64_t>("uint64"),    Type<double>("double"),
    Type<float>("float"),     Type<std::string>("string"), Type<std::vector<std::string>>("list"),
};

const FlagType* TypeOf(const absl::CommandLineFlag& flag) {
  for (const FlagType& t : kTypes) {
    if (t.is(flag)) return &t;
  }
  return nullptr;
}

}  // namespace

std::string FlagTypeName(const absl::CommandLineFlag& flag) {
  const FlagType* type = TypeOf(flag);
  return type != nullptr ? type->name : "value";
}

bool AcceptsValue(const absl::CommandLineFlag& flag, absl::string_view value) {
  const FlagType* type = TypeOf(flag);
  return type == nullptr || type->parses(value);
}

}  // namespace nupmpc::cli
