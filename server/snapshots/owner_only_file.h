#ifndef NUPMPC_SERVER_SNAPSHOTS_OWNER_ONLY_FILE_H_
#define NUPMPC_SERVER_SNAPSHOTS_OWNER_ONLY_FILE_H_

// Files only this server's user may read or write: the snapshot key and the snapshots.
// Checked on the open descriptor (no window between the check and the read), symbolic
// links refused.

#include <cstddef>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace nupmpc::server {

// The content of `path`, a regular file owned by this process's user, with no permission
// for group or others, of at most `max_bytes`. FAILED_PRECONDITION (or NOT_FOUND) naming
// `what` and the path otherwise.
absl::StatusOr<std::string> ReadOwnerOnlyFile(const std::string& path, std::size_t max_bytes, absl::string_view what);

// Writes `bytes` to `path` with mode 0600 so that a reader sees the old file or the whole
// new one, never a torn one: a temporary file beside it, flushed to disk, renamed over it.
absl::Status WriteOwnerOnlyFileAtomically(const std::string& path, absl::string_view bytes);

// Creates `dir` (mode 0700) if missing; an existing one must be a directory of this user
// that group and others cannot write. FAILED_PRECONDITION naming `what` otherwise.
absl::Status PrepareOwnerOnlyDirectory(const std::string& dir, absl::string_view what);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SNAPSHOTS_OWNER_ONLY_FILE_H_
