// What a session refuses to restore: truncated, altered, foreign-version or left-over
// bytes, another shape and another algorithm; always INVALID_ARGUMENT naming the field,
// never a crash (this test also runs under the sanitizers).

#include <cstdint>
#include <cstring>
#include <memory>
#include <string>

#include "core/session/session.h"
#include "gtest/gtest.h"
#include "tests/util/benchmark_files.h"
#include "tests/util/random_problem.h"

namespace nupmpc::core {
namespace {

using ::nupmpc::testing::LoadInstanceOrDie;

bool Mentions(const absl::Status& status, const std::string& text) {
  return std::string(status.message()).find(text) != std::string::npos;
}

// A session of `problem` after two closed-loop steps, and its snapshot.
std::string SnapshotAfterTwoSteps(const Problem& problem, const SolverOptions& options = {}) {
  absl::StatusOr<std::unique_ptr<Session>> s = Session::Create(problem, options);
  EXPECT_TRUE(s.ok()) << s.status();
  for (int step = 0; step < 2; ++step) {
    Solution plan;
    EXPECT_TRUE((*s)->Solve(&plan).ok());
    (*s)->ShiftWarmStart();
    EXPECT_TRUE((*s)->SetInitialState(plan.states.row(1).transpose()).ok());
  }
  std::string bytes;
  EXPECT_TRUE((*s)->SaveState(&bytes).ok());
  return bytes;
}

absl::Status RestoreInto(const Problem& problem, std::string_view bytes, const SolverOptions& options = {}) {
  absl::StatusOr<std::unique_ptr<Session>> s = Session::Create(problem, options);
  EXPECT_TRUE(s.ok()) << s.status();
  const absl::Status restored = (*s)->RestoreState(bytes);
  if (restored.ok()) {
    // Restored values may be nonsense (a flipped byte in a carried state); solving them
    // must still be safe.
    Solution plan;
    EXPECT_TRUE((*s)->Solve(&plan).ok());
  }
  return restored;
}

TEST(SnapshotRefusal, EveryTruncationIsRefused) {
  const Problem p = LoadInstanceOrDie("masses_N30").problem;
  const std::string bytes = SnapshotAfterTwoSteps(p);
  ASSERT_TRUE(RestoreInto(p, bytes).ok());
  // Every length within the header and the first records, then a dense sample, and the end.
  for (std::size_t length = 0; length < bytes.size(); length += length < 512 || length + 64 > bytes.size() ? 1 : 37) {
    const absl::Status status = RestoreInto(p, std::string_view(bytes).substr(0, length));
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << length << " of " << bytes.size() << ": " << status;
  }
}

TEST(SnapshotRefusal, LeftOverBytesAreRefused) {
  const Problem p = LoadInstanceOrDie("masses_N30").problem;
  const absl::Status status = RestoreInto(p, SnapshotAfterTwoSteps(p) + std::string(8, '\0'));
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Mentions(status, "left over")) << status;
}

TEST(SnapshotRefusal, AnotherFormatVersionIsRefusedNamingTheVersion) {
  const Problem p = LoadInstanceOrDie("masses_N30").problem;
  const std::string bytes = SnapshotAfterTwoSteps(p);
  for (std::size_t i = 0; i < 12; ++i) {  // the magic, then the version
    std::string altered = bytes;
    altered[i] = static_cast<char>(altered[i] + 1);
    const absl::Status status = RestoreInto(p, altered);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << i;
    EXPECT_TRUE(Mentions(status, "version")) << i << ": " << status;
  }
}

TEST(SnapshotRefusal, AnotherHorizonIsRefusedNamingAField) {
  testing::RandomProblemSpec spec{.N = 20};
  const Problem short_one = testing::WithBoxes(testing::RandomGaussianProblem(spec), 1.0, 0.0);
  spec.N = 21;
  const Problem long_one = testing::WithBoxes(testing::RandomGaussianProblem(spec), 1.0, 0.0);
  const absl::Status status = RestoreInto(long_one, SnapshotAfterTwoSteps(short_one));
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Mentions(status, "session.problem.")) << status;
}

TEST(SnapshotRefusal, AnotherAlgorithmIsRefused) {
  const Problem p = LoadInstanceOrDie("masses_N30").problem;
  SolverOptions iake;
  iake.algorithm = Algorithm::kIake;
  const absl::Status status = RestoreInto(p, SnapshotAfterTwoSteps(p), iake);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Mentions(status, "session.algorithm")) << status;
}

TEST(SnapshotRefusal, InvalidRestoredValuesAreRefusedLikeAnUpdate) {
  // Values an update would refuse (a negative weight) are refused on restore too.
  const Problem p = LoadInstanceOrDie("masses_N30").problem;
  absl::StatusOr<std::unique_ptr<Session>> s = Session::Create(p);
  ASSERT_TRUE(s.ok());
  std::string bytes;
  ASSERT_TRUE((*s)->SaveState(&bytes).ok());
  // The first input prior's variance: the second double of the input priors' "values"
  // record (after its type and name bytes and three uint64 shapes).
  const std::size_t values = bytes.find("values", bytes.find("input_priors"));
  ASSERT_NE(values, std::string::npos);
  const std::size_t at = values + 6 + 3 * sizeof(std::uint64_t) + sizeof(double);
  double stored = 0.0;
  std::memcpy(&stored, bytes.data() + at, sizeof(double));
  ASSERT_EQ(stored, p.input_priors[0].variance);  // the layout this test assumes
  const double negative = -1.0;
  bytes.replace(at, sizeof(double), reinterpret_cast<const char*>(&negative), sizeof(double));
  const absl::Status status = RestoreInto(p, bytes);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Mentions(status, "session.problem")) << status;
}

TEST(SnapshotRefusal, FlippedBytesAreRefusedOrRestoredNeverACrash) {
  const Problem p = LoadInstanceOrDie("masses_N30").problem;
  const std::string bytes = SnapshotAfterTwoSteps(p);
  for (std::size_t i = 12; i < bytes.size(); i += 31) {
    std::string altered = bytes;
    altered[i] = static_cast<char>(~altered[i]);
    const absl::Status status = RestoreInto(p, altered);
    EXPECT_TRUE(status.ok() || status.code() == absl::StatusCode::kInvalidArgument) << i << ": " << status;
  }
}

}  // namespace
}  // namespace nupmpc::core
