// The memory budget's bookkeeping, and exceptions that must end one request, not the server.
#include "server/sessions/memory_budget.h"

#include <unistd.h>

#include <new>
#include <stdexcept>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/rpc/catch_exceptions.h"

namespace nupmpc::server {
namespace {

using ::testing::HasSubstr;

TEST(MemoryBudget, ReservationsAreRefusedOverTheCapacityAndGivenBackWhenDestroyed) {
  MemoryBudget budget(100);
  auto a = budget.Reserve(60, "a");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(budget.reserved(), 60);
  auto b = budget.Reserve(50, "spec (b)");
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(b.status().message()), HasSubstr("spec (b)"));
  EXPECT_EQ(budget.reserved(), 60);
  {
    auto c = budget.Reserve(40, "c");
    ASSERT_TRUE(c.ok());
    EXPECT_EQ(budget.reserved(), 100);
  }
  EXPECT_EQ(budget.reserved(), 60);
  a->Release();
  EXPECT_EQ(budget.reserved(), 0);
}

TEST(MemoryBudget, SplitShrinkAndGrowKeepTheTotalRight) {
  MemoryBudget budget(100);
  auto r = budget.Reserve(80, "r");
  ASSERT_TRUE(r.ok());
  MemoryBudget::Reservation scratch = r->Split(30);
  EXPECT_EQ(r->bytes(), 50);
  EXPECT_EQ(scratch.bytes(), 30);
  EXPECT_EQ(budget.reserved(), 80);
  scratch.Release();
  EXPECT_EQ(budget.reserved(), 50);
  EXPECT_FALSE(scratch.GrowTo(60, "too much").ok());  // 50 + 60 > 100
  EXPECT_EQ(budget.reserved(), 50);
  EXPECT_TRUE(scratch.GrowTo(30, "scratch").ok());
  EXPECT_EQ(budget.reserved(), 80);
  r->ShrinkTo(10);
  EXPECT_EQ(budget.reserved(), 40);
  MemoryBudget::Reservation moved = std::move(*r);
  EXPECT_EQ(budget.reserved(), 40);
}

TEST(MemoryBudget, ConcurrentReservationsNeverExceedTheCapacity) {
  MemoryBudget budget(1000);
  std::vector<std::thread> threads;
  std::atomic<int> granted{0};
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&] {
      std::vector<MemoryBudget::Reservation> held;
      for (int i = 0; i < 1000; ++i) {
        auto r = budget.Reserve(7, "x");
        if (r.ok()) {
          ++granted;
          EXPECT_LE(budget.reserved(), 1000);
          held.push_back(*std::move(r));
        }
        if (held.size() > 10) held.erase(held.begin());
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_GT(granted.load(), 0);
  EXPECT_EQ(budget.reserved(), 0);
}

TEST(MemoryBudget, TheDefaultIsAShareOfTheMachinesMemory) {
  const std::int64_t budget = DefaultMemoryBudgetBytes();
  EXPECT_GT(budget, 64LL << 20);
  EXPECT_LT(budget, static_cast<std::int64_t>(sysconf(_SC_PHYS_PAGES)) * sysconf(_SC_PAGESIZE));
}

TEST(CatchExceptions, AnAllocationFailureBecomesResourceExhaustedAndAnythingElseInternal) {
  const absl::Status oom = RunCatchingExceptions("CreateSession", []() -> absl::Status { throw std::bad_alloc(); });
  EXPECT_EQ(oom.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(oom.message()), HasSubstr("CreateSession"));
  const absl::Status bug =
      RunCatchingExceptions("Solve", []() -> absl::Status { throw std::runtime_error("vector::_M_range_check"); });
  EXPECT_EQ(bug.code(), absl::StatusCode::kInternal);
  EXPECT_THAT(std::string(bug.message()), HasSubstr("_M_range_check"));
  EXPECT_EQ(RunCatchingExceptions("x", [] { return absl::NotFoundError("n"); }).code(), absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace nupmpc::server
