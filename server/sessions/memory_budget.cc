#include "server/sessions/memory_budget.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <fstream>
#include <optional>
#include <string>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "core/public/status_macros.h"

namespace nupmpc::server {
namespace {
std::string Mib(std::int64_t bytes) { return absl::StrCat((bytes + (1 << 20) - 1) >> 20, " MiB"); }
}  // namespace

struct MemoryBudget::Reservation::Counter {
  explicit Counter(std::int64_t c) : capacity(c) {}
  const std::int64_t capacity;
  std::atomic<std::int64_t> reserved{0};
};

MemoryBudget::Reservation::Reservation(Reservation&& other) noexcept
    : counter_(std::move(other.counter_)), bytes_(other.bytes_) {
  other.bytes_ = 0;
}

MemoryBudget::Reservation& MemoryBudget::Reservation::operator=(Reservation&& other) noexcept {
  if (this != &other) {
    Release();
    counter_ = std::move(other.counter_);
    bytes_ = other.bytes_;
    other.bytes_ = 0;
  }
  return *this;
}

void MemoryBudget::Reservation::Release() { ShrinkTo(0); }

void MemoryBudget::Reservation::ShrinkTo(std::int64_t bytes) {
  if (counter_ == nullptr || bytes >= bytes_) return;
  counter_->reserved.fetch_sub(bytes_ - std::max<std::int64_t>(bytes, 0), std::memory_order_relaxed);
  bytes_ = std::max<std::int64_t>(bytes, 0);
}

MemoryBudget::Reservation MemoryBudget::Reservation::Split(std::int64_t bytes) {
  bytes = std::clamp<std::int64_t>(bytes, 0, bytes_);
  bytes_ -= bytes;
  return Reservation(counter_, bytes);
}

absl::Status MemoryBudget::Reservation::GrowTo(std::int64_t bytes, absl::string_view purpose) {
  if (counter_ == nullptr || bytes <= bytes_) return absl::OkStatus();
  NUPMPC_ASSIGN_OR_RETURN(Reservation more, Take(counter_, bytes - bytes_, purpose));
  bytes_ += more.bytes_;
  more.bytes_ = 0;
  return absl::OkStatus();
}

MemoryBudget::MemoryBudget(std::int64_t capacity_bytes)
    : counter_(std::make_shared<Reservation::Counter>(capacity_bytes)) {}

absl::StatusOr<MemoryBudget::Reservation> MemoryBudget::Take(const std::shared_ptr<Reservation::Counter>& counter,
                                                             std::int64_t bytes, absl::string_view purpose) {
  bytes = std::max<std::int64_t>(bytes, 0);
  std::int64_t reserved = counter->reserved.load(std::memory_order_relaxed);
  do {
    if (bytes > counter->capacity - reserved) {
      return absl::ResourceExhaustedError(absl::StrCat(
          purpose, ": needs an estimated ", Mib(bytes),
          " of memory; the server's memory budget (--memory_budget_mb) of ", Mib(counter->capacity), " has ",
          Mib(counter->capacity - reserved), " left; close sessions, shrink the problem, or retry later"));
    }
  } while (!counter->reserved.compare_exchange_weak(reserved, reserved + bytes, std::memory_order_relaxed));
  return Reservation(counter, bytes);
}

absl::StatusOr<MemoryBudget::Reservation> MemoryBudget::Reserve(std::int64_t bytes, absl::string_view purpose) {
  return Take(counter_, bytes, purpose);
}

std::int64_t MemoryBudget::capacity() const { return counter_->capacity; }
std::int64_t MemoryBudget::reserved() const { return counter_->reserved.load(std::memory_order_relaxed); }

namespace {

// A cgroup memory limit file's value in bytes; none for "max", absent or unreadable files.
std::optional<std::int64_t> ReadLimit(const char* path) {
  std::ifstream file(path);
  std::string text;
  if (!std::getline(file, text)) return std::nullopt;
  std::int64_t value = 0;
  if (!absl::SimpleAtoi(absl::StripAsciiWhitespace(text), &value) || value <= 0) return std::nullopt;
  return value;
}

}  // namespace

std::int64_t DefaultMemoryBudgetBytes() {
  std::int64_t usable = static_cast<std::int64_t>(sysconf(_SC_PHYS_PAGES)) * sysconf(_SC_PAGESIZE);
  // cgroup v2, then v1 (whose "no limit" is a huge number, larger than physical memory).
  for (const char* path : {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
    if (const std::optional<std::int64_t> limit = ReadLimit(path)) usable = std::min(usable, *limit);
  }
  return usable / 4 * 3;
}

}  // namespace nupmpc::server
