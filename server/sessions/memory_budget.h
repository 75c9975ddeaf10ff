#ifndef NUPMPC_SERVER_SESSIONS_MEMORY_BUDGET_H_
#define NUPMPC_SERVER_SESSIONS_MEMORY_BUDGET_H_

#include <cstdint>
#include <memory>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace nupmpc::server {

// The server-wide memory budget (--memory_budget_mb). Everything a request would allocate
// in proportion to its size (a session's problem, scratch and GP factors, a one-off solve,
// a GP fit) is reserved here, from its estimate, before it is allocated; what does not fit
// is refused with RESOURCE_EXHAUSTED instead of being attempted. Thread-safe.
class MemoryBudget {
 public:
  // A share of the budget, given back when destroyed (or Release()d). Move-only; it may
  // outlive the MemoryBudget it came from.
  class Reservation {
   public:
    Reservation() = default;
    Reservation(Reservation&& other) noexcept;
    Reservation& operator=(Reservation&& other) noexcept;
    Reservation(const Reservation&) = delete;
    Reservation& operator=(const Reservation&) = delete;
    ~Reservation() { Release(); }

    std::int64_t bytes() const { return bytes_; }
    void Release();
    // Gives back all but `bytes` (no-op when it holds less).
    void ShrinkTo(std::int64_t bytes);
    // Moves `bytes` of this reservation (at most all of it) into a new one.
    Reservation Split(std::int64_t bytes);
    // Reserves more from the same budget until it holds `bytes`; RESOURCE_EXHAUSTED naming
    // `purpose` when the budget has not enough left (it then holds what it held).
    absl::Status GrowTo(std::int64_t bytes, absl::string_view purpose);

   private:
    friend class MemoryBudget;
    struct Counter;
    Reservation(std::shared_ptr<Counter> counter, std::int64_t bytes) : counter_(std::move(counter)), bytes_(bytes) {}
    std::shared_ptr<Counter> counter_;
    std::int64_t bytes_ = 0;
  };

  explicit MemoryBudget(std::int64_t capacity_bytes);

  // Reserves `bytes` for `purpose` (named in the refusal, e.g. "spec (the session)").
  absl::StatusOr<Reservation> Reserve(std::int64_t bytes, absl::string_view purpose);

  std::int64_t capacity() const;
  std::int64_t reserved() const;

 private:
  static absl::StatusOr<Reservation> Take(const std::shared_ptr<Reservation::Counter>& counter, std::int64_t bytes,
                                          absl::string_view purpose);
  std::shared_ptr<Reservation::Counter> counter_;
};

// The default budget: 3/4 of the memory this process may use, the smaller of the
// machine's physical memory and its cgroup (container) limit.
std::int64_t DefaultMemoryBudgetBytes();

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_MEMORY_BUDGET_H_
