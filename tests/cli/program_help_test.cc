// Every program built from this tree, run as a newcomer would: --help (and -h, --helpfull)
// describes the program and its own flags and exits 0 without doing anything; an unknown
// flag is refused with exit 2 and a pointer to --help. Each run happens in an empty
// working directory, which must still be empty afterwards (the example programs used to
// run in full and write their CSV files into a directory named "--help").
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

struct Program {
  const char* name;
  const char* own_flag;     // one flag the program defines itself
  const char* environment;  // a variable its help must mention ("" for none)
};

// What to expect of each program. CMake passes the paths of every executable target
// outside tests/ in NUPMPC_PROGRAMS (comma-separated); ProgramList checks that this table
// covers them all, so a new program cannot skip these checks.
const Program kPrograms[] = {
    {"nupmpc-server", "--address=<string>", "NUPMPC_"},
    {"nupmpc", "--format=<string>", "NUPMPC_SERVER"},
    {"nupmpc-bench", "--repeat=<int>", ""},
    {"nupmpc-loadtest", "--concurrency=<int>", "NUPMPC_SERVER"},
    {"nupmpc-api-example-bicycle", "--server=<string>", "NUPMPC_SERVER"},
    {"nupmpc-api-example-race-track", "--server=<string>", "NUPMPC_SERVER"},
    {"nupmpc-scaleout-probe", "--streams=<int>", "NUPMPC_SERVER"},
    {"nupmpc-loadtest-peer", "--echo_busy_us=<string>", ""},
    {"nupmpc-metrics-cost", "--sessions=<int>", ""},
    {"nupmpc-snapshot-cost", "--sessions=<int>", ""},
    {"nupmpc-period-groups", "--seconds=<double>", "NUPMPC_SERVER"},
    {"nupmpc-gp-bench", "--sizes=<string>", ""},
    {"nupmpc-example-dac", "--out_dir=<string>", ""},
    {"nupmpc-example-corridor", "--out_dir=<string>", ""},
    {"nupmpc-example-flappy-bird", "--out_dir=<string>", ""},
    {"nupmpc-example-obstacle-avoidance", "--out_dir=<string>", ""},
    {"nupmpc-example-race-track", "--steps=<int>", ""},
};

std::vector<std::string> BuiltPrograms() { return absl::StrSplit(NUPMPC_PROGRAMS, ',', absl::SkipEmpty()); }

std::string PathOf(const std::string& name) {
  for (const std::string& path : BuiltPrograms()) {
    if (std::filesystem::path(path).filename() == name) return path;
  }
  return "";
}

struct Output {
  int exit_code = -1;  // 128 + signal if killed
  std::string out, err;
};

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Runs `path args...` in the empty directory `cwd`, its output captured in files beside it.
Output RunIn(const std::filesystem::path& cwd, const std::string& path, const std::vector<std::string>& args) {
  const std::filesystem::path out = cwd.parent_path() / "stdout", err = cwd.parent_path() / "stderr";
  const pid_t pid = fork();
  if (pid == 0) {
    // A program that ignores --help would run its whole job: stop it after a minute.
    alarm(60);
    const int out_fd = open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err_fd = open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (out_fd < 0 || err_fd < 0 || chdir(cwd.c_str()) != 0) _exit(126);
    dup2(out_fd, STDOUT_FILENO);
    dup2(err_fd, STDERR_FILENO);
    std::vector<char*> argv = {const_cast<char*>(path.c_str())};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(path.c_str(), argv.data());
    _exit(127);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  Output run;
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  run.out = ReadFile(out);
  run.err = ReadFile(err);
  return run;
}

class ProgramHelpTest : public ::testing::TestWithParam<Program> {
 protected:
  void SetUp() override {
    path_ = PathOf(GetParam().name);
    ASSERT_FALSE(path_.empty()) << GetParam().name << " is not among the built programs: " << NUPMPC_PROGRAMS;
    char pattern[] = "/tmp/nupmpc_help_XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    root_ = pattern;
    cwd_ = root_ / "cwd";
    std::filesystem::create_directory(cwd_);
  }
  void TearDown() override {
    if (!root_.empty()) std::filesystem::remove_all(root_);
  }
  Output Start(const std::vector<std::string>& args) { return RunIn(cwd_, path_, args); }
  bool LeftNothingBehind() const { return std::filesystem::is_empty(cwd_); }

  std::string path_;
  std::filesystem::path root_, cwd_;
};

TEST_P(ProgramHelpTest, HelpListsOwnFlagsAndExitsZero) {
  const Program& p = GetParam();
  for (const char* help : {"--help", "-h", "--helpfull"}) {
    SCOPED_TRACE(help);
    const Output run = Start({help});
    EXPECT_EQ(run.exit_code, 0) << run.err;
    EXPECT_THAT(run.out, HasSubstr(std::string(p.name) + ":"));  // the summary names the program
    EXPECT_THAT(run.out, HasSubstr("\nUsage: " + std::string(p.name)));
    EXPECT_THAT(run.out, HasSubstr("\n  " + std::string(p.own_flag) + "  (default "));
    EXPECT_THAT(run.out, HasSubstr(p.environment));
    // Abseil's flags are not the program's, nor is its "No flags matched" fallback.
    for (const char* internal : {"--flagfile", "--fromenv", "--tryfromenv", "--undefok", "No flags matched"}) {
      EXPECT_THAT(run.out, Not(HasSubstr(internal)));
    }
    EXPECT_EQ(run.err, "");
    EXPECT_TRUE(LeftNothingBehind());
  }
}

TEST_P(ProgramHelpTest, UnknownFlagExitsTwoPointingToHelp) {
  const std::string name = GetParam().name;
  const Output run = Start({"--frobnicate"});
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_THAT(run.err, HasSubstr(name + ": unknown flag --frobnicate (see " + name + " --help)\n"));
  EXPECT_EQ(run.out, "");
  EXPECT_TRUE(LeftNothingBehind());
}

TEST_P(ProgramHelpTest, MisspeltFlagGetsASuggestion) {
  const std::string name = GetParam().name;
  const std::string flag = std::string(GetParam().own_flag).substr(2, std::string(GetParam().own_flag).find('=') - 2);
  const Output run = Start({"--" + flag.substr(0, flag.size() - 1) + "x=1"});  // last letter wrong
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_THAT(run.err, HasSubstr(name + ": did you mean --" + flag + "?\n"));
  EXPECT_TRUE(LeftNothingBehind());
}

// Named after the program without its "nupmpc-" prefix (ctest names stay short).
INSTANTIATE_TEST_SUITE_P(Programs, ProgramHelpTest, ::testing::ValuesIn(kPrograms),
                         [](const ::testing::TestParamInfo<Program>& info) {
                           std::string name = info.param.name;
                           if (name.rfind("nupmpc-", 0) == 0) name.erase(0, 7);
                           for (char& c : name) c = c == '-' ? '_' : c;
                           return name;
                         });

TEST(ProgramList, EveryBuiltProgramIsChecked) {
  std::vector<std::string> checked;
  for (const Program& p : kPrograms) checked.push_back(p.name);
  std::vector<std::string> built;
  for (const std::string& path : BuiltPrograms()) built.push_back(std::filesystem::path(path).filename());
  EXPECT_THAT(built, ::testing::UnorderedElementsAreArray(checked));
}

}  // namespace
}  // namespace nupmpc::testing
