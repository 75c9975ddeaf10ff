#include "core/snapshot/state_archive.h"

#include <algorithm>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace nupmpc::core {
namespace {

constexpr char kMagic[8] = {'N', 'U', 'P', 'S', 'T', 'A', 'T', 'E'};
constexpr std::size_t kHeaderSize = sizeof(kMagic) + sizeof(std::uint32_t);

// This Abseil's string_view is its own type, not std::string_view.
absl::string_view View(std::string_view s) { return {s.data(), s.size()}; }

}  // namespace

StateArchive::StateArchive(std::string* out) : out_(out) {
  std::uint32_t version = kSessionStateVersion;
  out->append(kMagic, sizeof(kMagic));
  out->append(reinterpret_cast<const char*>(&version), sizeof(version));
}

StateArchive::StateArchive(std::string_view in) : in_(in.data()), in_size_(in.size()) {
  // A reader needs a non-null pointer even for empty input: restoring() tests it.
  static constexpr char kEmpty = 0;
  if (in_ == nullptr) in_ = &kEmpty;
  // Every way the header can differ is a version question for the caller: bytes of
  // another format (or none) are never read as this one's.
  const auto refuse = [&](std::string_view why) {
    Fail("version", absl::StrCat(View(why), "; this build reads format version ", kSessionStateVersion));
  };
  if (in.size() < kHeaderSize) {
    refuse(absl::StrCat("only ", in.size(), " bytes, no header"));
  } else if (std::memcmp(in_, kMagic, sizeof(kMagic)) != 0) {
    refuse("not a session snapshot (magic)");
  } else if (std::uint32_t version = 0;
             std::memcpy(&version, in_ + sizeof(kMagic), sizeof(version)), version != kSessionStateVersion) {
    refuse(absl::StrCat("format version ", version));
  } else {
    position_ = kHeaderSize;
  }
}

StateWriter::StateWriter(std::string* out) : StateArchive(out) {}

StateReader::StateReader(std::string_view bytes) : StateArchive(bytes) {}

void StateArchive::Fail(std::string_view name, std::string_view why) {
  if (!status_.ok()) return;  // the first failure is the one that explains the others
  status_ = absl::InvalidArgumentError(absl::StrCat("session snapshot: ", path_, View(name), ": ", View(why)));
}

absl::Status StateArchive::status() const {
  if (!status_.ok() || !restoring() || position_ == in_size_) return status_;
  return absl::InvalidArgumentError(
      absl::StrCat("session snapshot: ", in_size_ - position_, " bytes left over after the last field"));
}

bool StateArchive::Reserve(std::string_view name, std::size_t bytes) {
  if (!ok()) return false;
  if (!restoring() || bytes <= in_size_ - position_) return true;
  Fail(name, absl::StrCat("truncated (", bytes, " bytes announced, ", in_size_ - position_, " left)"));
  return false;
}

bool StateArchive::Raw(std::string_view name, void* data, std::size_t size) {
  if (!ok()) return false;
  if (!restoring()) {
    out_->append(static_cast<const char*>(data), size);
    return true;
  }
  if (!Reserve(name, size)) return false;
  if (size > 0) std::memcpy(data, in_ + position_, size);
  position_ += size;
  return true;
}

bool StateArchive::Header(Type type, std::string_view name) {
  if (!ok()) return false;
  // Names are short identifiers written by this program: longer ones are a bug.
  const auto name_size = static_cast<std::uint8_t>(std::min<std::size_t>(name.size(), 255));
  if (!restoring()) {
    out_->push_back(static_cast<char>(type));
    out_->push_back(static_cast<char>(name_size));
    out_->append(name.data(), name_size);
    return true;
  }
  std::uint8_t stored[2] = {0, 0};
  if (!Raw(name, stored, sizeof(stored)) || !Reserve(name, stored[1])) return false;
  const std::string_view stored_name(in_ + position_, stored[1]);
  position_ += stored[1];
  if (stored_name != name.substr(0, name_size) || stored[0] != static_cast<std::uint8_t>(type)) {
    Fail(name, absl::StrCat("expected here, found record '", View(stored_name), "' of type ", int{stored[0]},
                            " (not type ", static_cast<int>(type), ")"));
    return false;
  }
  return true;
}

bool StateArchive::Shape(std::string_view name, std::uint64_t expected) {
  std::uint64_t stored = expected;
  if (!Raw(name, &stored, sizeof(stored))) return false;
  if (stored == expected) return true;
  Fail(name, absl::StrCat("stored size ", stored, " differs from this session's ", expected));
  return false;
}

void StateArchive::Number(std::string_view name, double& value) {
  if (Header(Type::kNumber, name)) Raw(name, &value, sizeof(value));
}

void StateArchive::Integer(std::string_view name, std::int64_t& value) {
  if (Header(Type::kInteger, name)) Raw(name, &value, sizeof(value));
}

void StateArchive::Integer(std::string_view name, int& value, int min, int max) {
  std::int64_t wide = value;
  Integer(name, wide);
  if (!restoring() || !ok()) return;
  if (wide < min || wide > max) return Fail(name, absl::StrCat(wide, " is outside [", min, ", ", max, "]"));
  value = static_cast<int>(wide);
}

void StateArchive::Flag(std::string_view name, bool& value) {
  std::uint8_t byte = value ? 1 : 0;
  if (!Header(Type::kFlag, name) || !Raw(name, &byte, 1) || !restoring()) return;
  if (byte > 1) return Fail(name, absl::StrCat("flag byte ", int{byte}, " is neither 0 nor 1"));
  value = byte == 1;
}

void StateArchive::Array(Type type, std::string_view name, void* data, std::uint64_t rows, std::uint64_t cols,
                         std::size_t element_size) {
  if (!Header(type, name) || !Shape(name, rows) || !Shape(name, cols) || !Shape(name, element_size)) return;
  // The shapes are this session's (compared above), so the size cannot overflow.
  Raw(name, data, rows * cols * element_size);
}

void StateArchive::Field(std::string_view name, Eigen::VectorXd& value) {
  Array(Type::kDoubles, name, value.data(), value.size(), 1, sizeof(double));
}

void StateArchive::Field(std::string_view name, Eigen::MatrixXd& value) {
  Array(Type::kDoubles, name, value.data(), value.rows(), value.cols(), sizeof(double));
}

void StateArchive::Field(std::string_view name, std::vector<double>& value) {
  Array(Type::kDoubles, name, value.data(), value.size(), 1, sizeof(double));
}

void StateArchive::Field(std::string_view name, std::vector<int>& value) {
  Array(Type::kInts, name, value.data(), value.size(), 1, sizeof(int));
}

void StateArchive::EnumeratorValues(std::string_view name, std::vector<std::int64_t>& values, std::int64_t first,
                                    std::int64_t last) {
  Array(Type::kInts, name, values.data(), values.size(), 1, sizeof(std::int64_t));
  if (!restoring() || !ok()) return;
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (values[i] < first || values[i] > last) {
      return Fail(name, absl::StrCat("element ", i, " = ", values[i], " is no enumerator ([", first, ", ", last, "])"));
    }
  }
}

void StateArchive::Blob(std::string_view name, std::string& value, std::size_t max_size) {
  std::uint64_t size = value.size();
  if (!Header(Type::kBlob, name) || !Raw(name, &size, sizeof(size))) return;
  if (!restoring()) {
    out_->append(value);
    return;
  }
  if (size > max_size) return Fail(name, absl::StrCat(size, " bytes exceed the bound ", max_size));
  if (!Reserve(name, size)) return;
  value.assign(in_ + position_, size);
  position_ += size;
}

void StateArchive::BeginSection(std::string_view name) {
  if (!Header(Type::kBegin, name)) return;
  absl::StrAppend(&path_, View(name), ".");
}

void StateArchive::EndSection() {
  if (!ok()) return;
  // The section's name once more, so a record that strays across a section's end is caught.
  // path_ is "outer.inner." here: the last name is between the last two dots.
  const std::size_t before = path_.size() < 2 ? std::string::npos : path_.rfind('.', path_.size() - 2);
  const std::size_t start = before == std::string::npos ? 0 : before + 1;
  const std::string name = path_.empty() ? std::string() : path_.substr(start, path_.size() - 1 - start);
  path_.resize(start);
  Header(Type::kEnd, name);
}

}  // namespace nupmpc::core
