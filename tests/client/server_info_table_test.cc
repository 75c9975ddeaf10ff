// `nupmpc info --format table`.
#include "client/server_info_table.h"

#include <limits>
#include <utility>

#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc {
namespace {

using ::testing::HasSubstr;

v1::GetServerInfoResponse Info() {
  v1::GetServerInfoResponse info;
  info.set_version("0.1.0");
  info.set_api_version("nupmpc.v1");
  info.set_cpu_baseline("x86-64-v3");
  info.set_cpu_features("avx avx2 fma");
  info.add_algorithms(v1::ALGORITHM_IAKE);
  info.add_algorithms(v1::ALGORITHM_IFFBDD);
  info.set_solves(42);
  info.set_solves_in_place(40);
  (*info.mutable_errors_by_code())["RESOURCE_EXHAUSTED"] = 2;
  (*info.mutable_errors_by_code())["INVALID_ARGUMENT"] = 3;
  info.set_active_sessions(5);
  info.set_resident_memory_bytes(3 << 20);
  const std::pair<double, int> buckets[] = {
      {0.5, 0}, {1.0, 40}, {2.0, 0}, {std::numeric_limits<double>::infinity(), 2}};
  for (const auto& [upper, count] : buckets) {
    v1::LatencyBucket* b = info.add_solve_latency();
    b->set_upper_ms(upper);
    b->set_count(count);
  }
  info.mutable_limits()->set_worker_threads(2);
  info.mutable_limits()->set_inline_solve_max_ms(2.0);
  info.mutable_limits()->set_max_message_bytes(64 << 20);
  info.mutable_limits()->set_first_message_timeout_s(10);
  info.mutable_limits()->set_connection_idle_timeout_s(600);
  return info;
}

TEST(ServerInfoTable, AlignedKeysAndReadableValues) {
  const std::string table = ServerInfoTable(Info());
  // Every value starts in the same column.
  std::size_t column = std::string::npos;
  for (const absl::string_view line : absl::StrSplit(table, '\n', absl::SkipEmpty())) {
    const std::size_t gap = line.find("  ");
    ASSERT_NE(gap, absl::string_view::npos) << line;
    const std::size_t value = line.find_first_not_of(' ', gap);
    if (column == std::string::npos) column = value;
    EXPECT_EQ(value, column) << line;
  }
  EXPECT_THAT(table, ::testing::StartsWith("version "));
  EXPECT_THAT(table, HasSubstr("x86-64-v3 (avx avx2 fma)\n"));
  EXPECT_THAT(table, HasSubstr("iake, iffbdd\n"));
  EXPECT_THAT(table, HasSubstr("INVALID_ARGUMENT 3, RESOURCE_EXHAUSTED 2\n"));  // sorted by code
  EXPECT_THAT(table, HasSubstr("≤1 ms: 40, >2 ms: 2\n"));                       // empty buckets left out
  EXPECT_THAT(table, HasSubstr("3.0 MiB\n"));
  EXPECT_THAT(table, HasSubstr("64.0 MiB\n"));
  EXPECT_THAT(table, HasSubstr("draining "));
  EXPECT_THAT(table, ::testing::ContainsRegex("solves +42 \\(40 on the gRPC thread that received them\\)\n"));
  EXPECT_THAT(table, ::testing::ContainsRegex("solved where received +steps of sessions solving in ≤2 ms\n"));
  EXPECT_THAT(table, ::testing::ContainsRegex("first message within +10 s\n"));
  EXPECT_THAT(table, ::testing::ContainsRegex("idle connections closed +600 s\n"));
  EXPECT_THAT(table, ::testing::Not(HasSubstr("{")));  // not JSON
}

TEST(ServerInfoTable, AnOlderServerWithoutCpuBaselineOrSolves) {
  v1::GetServerInfoResponse info = Info();
  info.clear_cpu_baseline();
  info.clear_solve_latency();
  info.clear_errors_by_code();
  info.mutable_limits()->clear_first_message_timeout_s();
  const std::string table = ServerInfoTable(info);
  EXPECT_THAT(table, HasSubstr("(not reported)\n"));
  EXPECT_THAT(table, HasSubstr("no solves yet\n"));
  EXPECT_THAT(table, ::testing::ContainsRegex("errors by code +none\n"));
  EXPECT_THAT(table, ::testing::ContainsRegex("first message within +no limit\n"));  // not reported: 0
}

}  // namespace
}  // namespace nupmpc
