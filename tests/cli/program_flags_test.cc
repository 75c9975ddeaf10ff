// The shared command-line library: which flags count as the program's own, the help text,
// the checks that run before Abseil parses, and the exit codes of ParseProgramFlags.
#include "cli/program_flags.h"

#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/reflection.h"
#include "cli/help_text.h"
#include "cli/own_flags.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

ABSL_FLAG(int, test_count, 3, "how many things to do");
ABSL_FLAG(bool, test_verbose, false, "say more");
ABSL_FLAG(std::string, test_name, "anna",
          "a name that is long enough to need wrapping when the help text is printed "
          "in a terminal that is only a hundred columns wide, which it is");
ABSL_FLAG(double, concurrency_level, 1.5, "for prefix suggestions");

namespace nupmpc::cli {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Not;
using Outcome = ArgumentCheck::Outcome;

const ProgramInfo kProgram{
    .name = "prog",
    .summary = "prog: does things.\n  a  first\n  b  second",
    .usage = "prog [FLAGS] FILE",
    .environment = {{"PROG_HOST", "where to connect when --test_name is not given"}},
    .max_arguments = 1,
};

ArgumentCheck Check(std::vector<std::string> args) { return CheckArguments(kProgram, args); }

std::vector<std::string> Names(const std::vector<absl::CommandLineFlag*>& flags) {
  std::vector<std::string> names;
  for (const absl::CommandLineFlag* f : flags) names.emplace_back(f->Name());
  return names;
}

TEST(OwnFlags, AreThisProgramsFlagsSortedWithoutAbseilsOwn) {
  // Abseil's parser registers --flagfile & co. in every program that links it; they must
  // exist here for the filter to be tested at all.
  ASSERT_NE(absl::FindCommandLineFlag("flagfile"), nullptr);
  EXPECT_THAT(Names(OwnFlags()), ElementsAre("concurrency_level", "test_count", "test_name", "test_verbose"));
  EXPECT_EQ(FindOwnFlag("flagfile"), nullptr);
  EXPECT_NE(FindOwnFlag("test_count"), nullptr);
}

TEST(OwnFlags, AbseilFilenamesAreRecognisedByTheirFolder) {
  EXPECT_TRUE(IsAbseilFilename("./absl/flags/parse.cc"));
  EXPECT_TRUE(IsAbseilFilename("absl/flags/parse.cc"));
  EXPECT_TRUE(IsAbseilFilename("/build/abseil-cpp/absl/flags/parse.cc"));
  EXPECT_FALSE(IsAbseilFilename("/work/nupmpc/server/server_flags.cc"));
  EXPECT_FALSE(IsAbseilFilename("/work/nupmpc/tests/cli/absl_like_name.cc"));
}

TEST(OwnFlags, TypeNames) {
  EXPECT_EQ(FlagTypeName(*FindOwnFlag("test_count")), "int");
  EXPECT_EQ(FlagTypeName(*FindOwnFlag("test_verbose")), "bool");
  EXPECT_EQ(FlagTypeName(*FindOwnFlag("test_name")), "string");
  EXPECT_EQ(FlagTypeName(*FindOwnFlag("concurrency_level")), "double");
}

TEST(HelpText, ListsSummaryUsageOwnFlagsWithDefaultsAndEnvironment) {
  const std::string help = HelpText(kProgram);
  EXPECT_THAT(help, HasSubstr("prog: does things.\n  a  first\n  b  second\n"));  // aligned lines kept
  EXPECT_THAT(help, HasSubstr("\nUsage: prog [FLAGS] FILE\n"));
  EXPECT_THAT(help, HasSubstr("  --test_count=<int>  (default 3)\n      how many things to do\n"));
  EXPECT_THAT(help, HasSubstr("  --test_verbose=<bool>  (default false)\n"));
  EXPECT_THAT(help, HasSubstr("  --test_name=<string>  (default \"anna\")\n"));
  EXPECT_THAT(help, HasSubstr("  -h, --help\n"));
  EXPECT_THAT(help, HasSubstr("\nEnvironment:\n  PROG_HOST  where to connect when --test_name is not given\n"));
  EXPECT_THAT(help, Not(HasSubstr("flagfile")));
  EXPECT_THAT(help, Not(HasSubstr("undefok")));
  EXPECT_THAT(help, Not(HasSubstr("fromenv")));
}

TEST(HelpText, ShowsAValueTheProgramTookFromTheEnvironment) {
  absl::FlagSaver restore;
  absl::SetFlag(&FLAGS_test_name, "bob");
  EXPECT_THAT(HelpText(kProgram), HasSubstr("--test_name=<string>  (default \"anna\"; from the environment \"bob\")"));
}

TEST(WrapText, WrapsLongLinesUnderTheirFirstWordAndKeepsShortOnes) {
  const std::string text = WrapText("  alpha beta gamma delta\nshort  line\n\nend", 2, 16);
  EXPECT_EQ(text, "    alpha beta\n    gamma delta\n  short  line\n\n  end\n");
  // A word longer than the width stands alone.
  EXPECT_EQ(WrapText(std::string(30, 'x') + " y", 0, 10), std::string(30, 'x') + "\ny\n");
}

TEST(CheckArguments, EveryHelpSpellingAsksForHelpEvenNextToErrors) {
  for (const char* help : {"--help", "-h", "--helpfull", "-help", "--helpshort"}) {
    EXPECT_EQ(Check({help}).outcome, Outcome::kHelp) << help;
  }
  EXPECT_EQ(Check({"--frobnicate", "--help"}).outcome, Outcome::kHelp);
  EXPECT_EQ(Check({"a", "b", "c", "-h"}).outcome, Outcome::kHelp);
}

TEST(CheckArguments, AnUnknownFlagIsAUsageErrorWithAHintWhenOneIsClose) {
  const ArgumentCheck unknown = Check({"--frobnicate"});
  EXPECT_EQ(unknown.outcome, Outcome::kUsageError);
  EXPECT_EQ(unknown.error, "unknown flag --frobnicate");
  EXPECT_EQ(unknown.hint, "");
  const ArgumentCheck typo = Check({"--test_cont=4"});
  EXPECT_EQ(typo.error, "unknown flag --test_cont");
  EXPECT_EQ(typo.hint, "did you mean --test_count?");
  // Abseil's own flags are not ours to accept.
  EXPECT_EQ(Check({"--flagfile=x"}).error, "unknown flag --flagfile");
}

TEST(SuggestFlag, DashesCapitalsPrefixesAndTypos) {
  EXPECT_EQ(SuggestFlag("test-count"), "test_count");
  EXPECT_EQ(SuggestFlag("TEST_NAME"), "test_name");
  EXPECT_EQ(SuggestFlag("concur"), "concurrency_level");
  EXPECT_EQ(SuggestFlag("test_verbos"), "test_verbose");
  EXPECT_EQ(SuggestFlag("hepl"), "help");
  EXPECT_EQ(SuggestFlag("frobnicate"), "");
  EXPECT_EQ(SuggestFlag("x"), "");
}

TEST(CheckArguments, ValuesAreCheckedAgainstTheFlagsType) {
  EXPECT_EQ(Check({"--test_count=abc"}).error, "bad value \"abc\" for --test_count (expects int)");
  EXPECT_EQ(Check({"--test_count", "abc"}).error, "bad value \"abc\" for --test_count (expects int)");
  EXPECT_EQ(Check({"--test_count"}).error, "flag --test_count needs a value (int)");
  EXPECT_EQ(Check({"--test_verbose=maybe"}).error, "bad value \"maybe\" for --test_verbose (expects bool)");
  EXPECT_EQ(Check({"--notest_verbose=true"}).error, "--notest_verbose takes no value");
  EXPECT_EQ(Check({"--notest_count"}).error,
            "--notest_count: only yes/no flags have a --no form; --test_count expects int");
}

TEST(CheckArguments, WellFormedCommandLinesAreLeftToAbseil) {
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
           {},
           {"FILE"},
           {"-"},  // stdin, by convention an argument
           {"--test_count=4", "FILE"},
           {"-test_count", "4", "FILE"},  // the value is the next argument, not a second file
           {"--test_verbose", "FILE"},    // a bool never takes the next argument
           {"--notest_verbose", "--test_verbose=false", "--test_name="},
           {"--", "--not-a-flag"},  // after "--" everything is an argument
       }) {
    const ArgumentCheck check = Check(args);
    EXPECT_EQ(check.outcome, Outcome::kParse) << check.error;
  }
}

TEST(CheckArguments, MoreArgumentsThanTheProgramTakesAreAnError) {
  EXPECT_EQ(Check({"one", "two"}).error, "unexpected argument \"two\"");
  EXPECT_EQ(Check({"one", "--", "--two"}).error, "unexpected argument \"--two\"");
  ProgramInfo any = kProgram;
  any.max_arguments = -1;
  EXPECT_EQ(CheckArguments(any, {"one", "two", "three"}).outcome, Outcome::kParse);
}

TEST(UsageErrorText, NamesTheProgramAndPointsToHelp) {
  EXPECT_EQ(UsageErrorText(kProgram, "unknown flag --x"), "prog: unknown flag --x (see prog --help)\n");
  EXPECT_EQ(UsageErrorText(kProgram, "unknown flag --x", "did you mean --y?"),
            "prog: unknown flag --x (see prog --help)\nprog: did you mean --y?\n");
}

// ParseProgramFlags on a copy of argv it may reorder.
std::vector<std::string> Parse(std::vector<std::string> args) {
  args.insert(args.begin(), "prog");
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  std::vector<std::string> positional;
  for (char* p : ParseProgramFlags(kProgram, static_cast<int>(argv.size()), argv.data())) positional.emplace_back(p);
  return positional;
}

TEST(ParseProgramFlags, SetsTheFlagsAndReturnsTheArguments) {
  absl::FlagSaver restore;
  EXPECT_THAT(Parse({"--test_count", "7", "FILE", "--test_verbose"}), ElementsAre("prog", "FILE"));
  EXPECT_EQ(absl::GetFlag(FLAGS_test_count), 7);
  EXPECT_TRUE(absl::GetFlag(FLAGS_test_verbose));
}

TEST(ParseProgramFlagsDeathTest, HelpExitsZeroAndUsageErrorsExitTwo) {
  EXPECT_EXIT(Parse({"--help"}), ::testing::ExitedWithCode(0), "");
  EXPECT_EXIT(Parse({"--frobnicate"}), ::testing::ExitedWithCode(2),
              "^prog: unknown flag --frobnicate \\(see prog --help\\)\n$");
  EXPECT_EXIT(Parse({"--test-count=2"}), ::testing::ExitedWithCode(2), "prog: did you mean --test_count\\?");
  EXPECT_EXIT(Parse({"a", "b"}), ::testing::ExitedWithCode(2), "unexpected argument \"b\"");
}

}  // namespace
}  // namespace nupmpc::cli
