#include "server/rpc/catch_exceptions.h"

#include <exception>
#include <new>

#include "absl/strings/str_cat.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {

absl::Status RunCatchingExceptions(const char* what, const std::function<absl::Status()>& work) {
  try {
    return work();
  } catch (const std::bad_alloc&) {
    spdlog::warn("{}: out of memory; the request was refused and the server goes on", what);
    return absl::ResourceExhaustedError(
        absl::StrCat(what, ": the server ran out of memory for this request; retry later or shrink the problem"));
  } catch (const std::exception& e) {
    spdlog::error("{}: internal error: {}", what, e.what());
    return absl::InternalError(absl::StrCat(what, ": internal error (", e.what(), ")"));
  } catch (...) {
    spdlog::error("{}: internal error (unknown exception)", what);
    return absl::InternalError(absl::StrCat(what, ": internal error"));
  }
}

}  // namespace nupmpc::server
