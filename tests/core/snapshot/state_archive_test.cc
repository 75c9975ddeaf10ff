// StateArchive: what one function writes, the same function reads back; and what it
// refuses (another type, name or shape, truncation, left-over bytes, out-of-range values).

#include "core/snapshot/state_archive.h"

#include <functional>
#include <string>
#include <vector>

#include "core/priors/scalar_factor.h"
#include "core/priors/scalar_rules.h"
#include "gtest/gtest.h"

namespace nupmpc::core {
namespace {

struct Sample {
  double number = 0.0;
  int count = 0;
  bool flag = false;
  Region region = Region::kInside;
  Eigen::VectorXd vector = Eigen::VectorXd::Zero(3);
  Eigen::MatrixXd matrix = Eigen::MatrixXd::Zero(2, 3);
  std::vector<ScalarFactor> factors = std::vector<ScalarFactor>(2);
  std::vector<Region> regions = std::vector<Region>(4, Region::kInside);
  std::string blob;

  void Persist(StateArchive& a) {
    a.BeginSection("sample");
    a.Number("number", number);
    a.Integer("count", count, 0, 10);
    a.Flag("flag", flag);
    a.Enumerator("region", region, Region::kBelow, Region::kAbove);
    a.Field("vector", vector);
    a.Field("matrix", matrix);
    a.Field("factors", factors);
    a.EnumeratorField("regions", regions, Region::kBelow, Region::kAbove);
    a.Blob("blob", blob, 16);
    a.EndSection();
  }
};

Sample Filled() {
  Sample s;
  s.number = -0.1;
  s.count = 7;
  s.flag = true;
  s.region = Region::kAtUpper;
  s.vector << 1, 2, 3;
  s.matrix << 1, 2, 3, 4, 5, 6;
  s.factors[1] = ScalarFactor{1.5, 2.5, 3.5, 4.5};
  s.regions = {Region::kBelow, Region::kAbove, Region::kAtLower, Region::kInside};
  s.blob = "inner";
  return s;
}

std::string Saved(Sample s) {
  std::string bytes;
  StateWriter writer(&bytes);
  s.Persist(writer);
  EXPECT_TRUE(writer.status().ok());
  return bytes;
}

absl::Status Restore(std::string_view bytes, Sample* into) {
  StateReader reader(bytes);
  into->Persist(reader);
  return reader.status();
}

TEST(StateArchive, RoundTrips) {
  Sample restored;
  ASSERT_TRUE(Restore(Saved(Filled()), &restored).ok());
  const Sample want = Filled();
  EXPECT_EQ(restored.number, want.number);
  EXPECT_EQ(restored.count, want.count);
  EXPECT_EQ(restored.flag, want.flag);
  EXPECT_EQ(restored.region, want.region);
  EXPECT_EQ(restored.vector, want.vector);
  EXPECT_EQ(restored.matrix, want.matrix);
  EXPECT_EQ(restored.factors[1].w, 4.5);
  EXPECT_EQ(restored.regions, want.regions);
  EXPECT_EQ(restored.blob, want.blob);
}

TEST(StateArchive, EveryTruncationIsRefused) {
  const std::string bytes = Saved(Filled());
  for (std::size_t length = 0; length < bytes.size(); ++length) {
    Sample restored;
    const absl::Status status = Restore(std::string_view(bytes).substr(0, length), &restored);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << length << ": " << status;
  }
}

TEST(StateArchive, LeftOverBytesAreRefused) {
  Sample restored;
  const absl::Status status = Restore(Saved(Filled()) + "x", &restored);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("left over"), std::string::npos) << status;
}

TEST(StateArchive, AnotherVersionOrMagicIsRefusedNamingTheVersion) {
  const std::string bytes = Saved(Filled());
  for (std::size_t i = 0; i < 12; ++i) {  // the magic and the version
    std::string altered = bytes;
    altered[i] = static_cast<char>(altered[i] ^ 0x01);
    Sample restored;
    const absl::Status status = Restore(altered, &restored);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << i;
    EXPECT_NE(status.message().find("version"), std::string::npos) << i << ": " << status;
  }
}

TEST(StateArchive, AnotherShapeIsRefusedNamingTheField) {
  Sample other = Filled();
  other.matrix = Eigen::MatrixXd::Zero(3, 3);
  Sample restored;
  const absl::Status status = Restore(Saved(other), &restored);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("sample.matrix"), std::string::npos) << status;
}

TEST(StateArchive, OutOfRangeValuesAreRefusedNamingTheField) {
  const std::string bytes = Saved(Filled());
  struct Case {
    const char* field;
    std::function<void(Sample*)> alter;
  };
  for (const Case& c : std::vector<Case>{{"sample.count", [](Sample* s) { s->count = 11; }},
                                         {"sample.region", [](Sample* s) { s->region = static_cast<Region>(3); }},
                                         {"sample.regions", [](Sample* s) { s->regions[2] = static_cast<Region>(-3); }},
                                         {"sample.blob", [](Sample* s) { s->blob = std::string(17, 'x'); }}}) {
    Sample altered = Filled();
    c.alter(&altered);
    Sample restored;
    const absl::Status status = Restore(Saved(altered), &restored);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << c.field;
    EXPECT_NE(status.message().find(c.field), std::string::npos) << status;
  }
}

TEST(StateArchive, FlippedBytesAreRefusedOrReadAsTheirValues) {
  // Past the header, a flipped byte changes a name, a type, a shape (refused) or a value
  // (read as that value: integrity is the snapshot file's checksum's job); never a crash.
  const std::string bytes = Saved(Filled());
  for (std::size_t i = 12; i < bytes.size(); ++i) {
    std::string altered = bytes;
    altered[i] = static_cast<char>(~altered[i]);
    Sample restored;
    const absl::Status status = Restore(altered, &restored);
    EXPECT_TRUE(status.ok() || status.code() == absl::StatusCode::kInvalidArgument) << i << ": " << status;
  }
}

}  // namespace
}  // namespace nupmpc::core
