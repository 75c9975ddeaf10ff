#ifndef NUPMPC_TESTS_UTIL_BENCHMARK_FILES_H_
#define NUPMPC_TESTS_UTIL_BENCHMARK_FILES_H_

// The benchmark instances of benchmarks/ (NUPMPC_BENCHMARK_DIR) for the tests that solve
// them; a test using these links nupmpc_instances.

#include <string>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"

namespace nupmpc::testing {

// benchmarks/<name>.json ("reference" for the reference optima).
inline std::string BenchmarkPath(const std::string& name) {
  // StrCat, not a chain of std::string operator+: GCC 12 warns falsely (-Warray-bounds) on
  // that chain where it inlines it (GCC bug 105651).
  return absl::StrCat(NUPMPC_BENCHMARK_DIR, "/", name, ".json");
}

// The instance, or a test failure naming why it did not load.
inline bench::BenchmarkInstance LoadInstanceOrDie(const std::string& name) {
  absl::StatusOr<bench::BenchmarkInstance> inst = bench::LoadBenchmarkInstance(BenchmarkPath(name));
  EXPECT_TRUE(inst.ok()) << inst.status();
  return *std::move(inst);
}

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_BENCHMARK_FILES_H_
