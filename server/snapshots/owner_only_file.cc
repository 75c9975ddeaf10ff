#include "server/snapshots/owner_only_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {
namespace {

// Closes a descriptor on every path out.
class Descriptor {
 public:
  explicit Descriptor(int fd) : fd_(fd) {}
  Descriptor(const Descriptor&) = delete;
  Descriptor& operator=(const Descriptor&) = delete;
  ~Descriptor() {
    if (fd_ >= 0) close(fd_);
  }
  int get() const { return fd_; }

 private:
  int fd_;
};

std::string Errno() { return std::strerror(errno); }

}  // namespace

absl::StatusOr<std::string> ReadOwnerOnlyFile(const std::string& path, std::size_t max_bytes, absl::string_view what) {
  const Descriptor fd(open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK));
  if (fd.get() < 0) {
    const std::string message = absl::StrCat(what, " ", path, ": cannot open: ", Errno());
    return errno == ENOENT ? absl::NotFoundError(message) : absl::FailedPreconditionError(message);
  }
  struct stat st {};
  if (fstat(fd.get(), &st) != 0) return absl::FailedPreconditionError(absl::StrCat(what, " ", path, ": ", Errno()));
  if (!S_ISREG(st.st_mode)) return absl::FailedPreconditionError(absl::StrCat(what, " ", path, ": not a regular file"));
  if (st.st_uid != geteuid() || (st.st_mode & (S_IRWXG | S_IRWXO)) != 0) {
    return absl::FailedPreconditionError(
        absl::StrCat(what, " ", path, ": must belong to this server's user and be readable by it only (chmod 600)"));
  }
  if (st.st_size < 0 || static_cast<std::size_t>(st.st_size) > max_bytes) {
    return absl::FailedPreconditionError(
        absl::StrCat(what, " ", path, ": ", st.st_size, " bytes, more than the ", max_bytes, " allowed"));
  }
  std::string bytes(static_cast<std::size_t>(st.st_size), '\0');
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = read(fd.get(), bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return absl::FailedPreconditionError(absl::StrCat(what, " ", path, ": short read"));
    done += static_cast<std::size_t>(n);
  }
  return bytes;
}

absl::Status WriteOwnerOnlyFileAtomically(const std::string& path, absl::string_view bytes) {
  const std::string temporary = absl::StrCat(path, ".tmp.", getpid());
  // A leftover of an earlier process with this pid goes first: created anew (O_EXCL), the
  // file gets mode 0600 whatever the leftover's was.
  unlink(temporary.c_str());
  {
    const Descriptor fd(open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0600));
    if (fd.get() < 0) return absl::FailedPreconditionError(absl::StrCat(temporary, ": cannot create: ", Errno()));
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = write(fd.get(), bytes.data() + done, bytes.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        const std::string why = Errno();
        unlink(temporary.c_str());
        return absl::FailedPreconditionError(absl::StrCat(temporary, ": cannot write: ", why));
      }
      done += static_cast<std::size_t>(n);
    }
    if (fsync(fd.get()) != 0) {
      const std::string why = Errno();
      unlink(temporary.c_str());
      return absl::FailedPreconditionError(absl::StrCat(temporary, ": cannot flush: ", why));
    }
  }
  if (rename(temporary.c_str(), path.c_str()) != 0) {
    const std::string why = Errno();
    unlink(temporary.c_str());
    return absl::FailedPreconditionError(absl::StrCat(path, ": cannot rename into place: ", why));
  }
  return absl::OkStatus();
}

absl::Status PrepareOwnerOnlyDirectory(const std::string& dir, absl::string_view what) {
  if (mkdir(dir.c_str(), 0700) != 0 && errno != EEXIST) {
    return absl::FailedPreconditionError(absl::StrCat(what, " ", dir, ": cannot create: ", Errno()));
  }
  struct stat st {};
  if (lstat(dir.c_str(), &st) != 0) return absl::FailedPreconditionError(absl::StrCat(what, " ", dir, ": ", Errno()));
  if (!S_ISDIR(st.st_mode)) return absl::FailedPreconditionError(absl::StrCat(what, " ", dir, ": not a directory"));
  if (st.st_uid != geteuid() || (st.st_mode & (S_IWGRP | S_IWOTH)) != 0) {
    return absl::FailedPreconditionError(
        absl::StrCat(what, " ", dir, ": must belong to this server's user, not writable by group or others"));
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::server
