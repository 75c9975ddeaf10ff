#ifndef NUPMPC_CORE_SNAPSHOT_STATE_ARCHIVE_H_
#define NUPMPC_CORE_SNAPSHOT_STATE_ARCHIVE_H_

// A session's state as bytes and back, for snapshots (a session that survives a restart or
// moves to another process). Every class with state writes ONE function that both saves
// and restores it, so the two directions cannot drift:
//
//   void Iffbdd::PersistState(StateArchive& archive, const Problem& problem) {
//     archive.Field("nup", nup_);
//     archive.Field("gamma", gamma_);
//     archive.Flag("has_duals", has_duals_);
//   }
//
// Restoring goes into a session rebuilt from the same creation spec, so every field
// already has its shape: a restore requires the stored shape to equal the current one
// (`Field`), or to stay within a bound the class states (`Integer` with a range, `Blob`).
// Records are matched by name and type in order; the first mismatch (another spec,
// another version, truncated or altered bytes) stops the archive with INVALID_ARGUMENT
// naming the field ("session.iffbdd.gamma"), and every later call is a no-op. Since shapes
// come from the receiving session, a reader never allocates more than that session holds
// or the input's length justifies (Reserve), and never reads past the input.
//
// The bytes: the magic "NUPSTATE" and kSessionStateVersion (little-endian uint32), then
// one record per call: a type byte, the name (length byte + bytes), the shape where the
// type has one (uint64s) and the values (little-endian IEEE doubles, int64 integers;
// x86-64 only). A reader refuses another version: a format change bumps it.
//
// Nothing here decides what is worth saving: that is each class's PersistState.

#include <cstdint>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"

namespace nupmpc::core {

// Bumped by every change of the record layout or of any class's PersistState.
inline constexpr std::uint32_t kSessionStateVersion = 1;

class StateArchive {
 public:
  StateArchive(const StateArchive&) = delete;
  StateArchive& operator=(const StateArchive&) = delete;
  virtual ~StateArchive() = default;

  bool restoring() const { return in_ != nullptr; }
  // Whether no record failed so far (a restore that failed must not go on using the values).
  bool ok() const { return status_.ok(); }

  // Scalars.
  void Number(std::string_view name, double& value);
  void Integer(std::string_view name, std::int64_t& value);
  // A restore refuses values outside [min, max] (indices, counts, shifts).
  void Integer(std::string_view name, int& value, int min, int max);
  void Flag(std::string_view name, bool& value);
  // An enum stored as its underlying integer; a restore refuses values outside
  // [first, last] (the enumerators must be contiguous).
  template <class Enum>
  void Enumerator(std::string_view name, Enum& value, Enum first, Enum last);

  // Fixed-shape arrays: on restore the stored shape must equal the current one.
  void Field(std::string_view name, Eigen::VectorXd& value);
  void Field(std::string_view name, Eigen::MatrixXd& value);
  void Field(std::string_view name, std::vector<double>& value);
  void Field(std::string_view name, std::vector<int>& value);
  // Plain structs of doubles (ScalarFactor, ...): stored as their bytes with sizeof(T).
  template <class Pod>
  void Field(std::string_view name, std::vector<Pod>& value);
  // Vectors of enums (Region, ...), each checked as in Enumerator.
  template <class Enum>
  void EnumeratorField(std::string_view name, std::vector<Enum>& value, Enum first, Enum last);

  // Bytes of another archive (a wrapped session's own snapshot), at most max_size long.
  void Blob(std::string_view name, std::string& value, std::size_t max_size);

  // Before a restore allocates for `bytes` of values still to come (a count it has just
  // read): false, and the archive stopped, if the input has fewer left. Writers: true.
  bool Reserve(std::string_view name, std::size_t bytes);

  // Groups the fields of one part under a name (for error messages: "iffbdd.gamma").
  void BeginSection(std::string_view name);
  void EndSection();

  // Stops the archive (restore) with INVALID_ARGUMENT "<sections>.<name>: <why>"; for the
  // checks a class makes itself (a value that must equal the session's own).
  void Fail(std::string_view name, std::string_view why);

  // The first failure; for a reader also whether bytes are left over after the last field.
  absl::Status status() const;

 protected:
  // A writer appends to `out`; a reader reads `in` (not owned).
  explicit StateArchive(std::string* out);
  explicit StateArchive(std::string_view in);

 private:
  enum class Type : std::uint8_t { kNumber = 1, kInteger, kFlag, kDoubles, kInts, kBytes, kBlob, kBegin, kEnd };

  // The record's type and name: written, or read and compared. False once stopped.
  bool Header(Type type, std::string_view name);
  // A shape value: written, or read and compared with `expected`.
  bool Shape(std::string_view name, std::uint64_t expected);
  // `size` raw bytes: written from, or read into, `data`.
  bool Raw(std::string_view name, void* data, std::size_t size);
  // Fixed-shape array of `count` elements of `element_size` bytes (a matrix: rows, cols).
  void Array(Type type, std::string_view name, void* data, std::uint64_t rows, std::uint64_t cols,
             std::size_t element_size);
  void EnumeratorValues(std::string_view name, std::vector<std::int64_t>& values, std::int64_t first,
                        std::int64_t last);

  std::string* out_ = nullptr;
  const char* in_ = nullptr;
  std::size_t in_size_ = 0, position_ = 0;
  std::string path_;  ///< the open sections, "session.iffbdd."
  absl::Status status_;
};

// Writes the header and then every record to `out` (appended).
class StateWriter final : public StateArchive {
 public:
  explicit StateWriter(std::string* out);
};

// Reads from `bytes` (not owned; must outlive the reader); checks the header first.
class StateReader final : public StateArchive {
 public:
  explicit StateReader(std::string_view bytes);
};

template <class Enum>
void StateArchive::Enumerator(std::string_view name, Enum& value, Enum first, Enum last) {
  std::vector<std::int64_t> values{static_cast<std::int64_t>(value)};
  EnumeratorValues(name, values, static_cast<std::int64_t>(first), static_cast<std::int64_t>(last));
  if (restoring() && ok()) value = static_cast<Enum>(values[0]);
}

template <class Enum>
void StateArchive::EnumeratorField(std::string_view name, std::vector<Enum>& value, Enum first, Enum last) {
  std::vector<std::int64_t> values(value.size());
  for (std::size_t i = 0; i < value.size(); ++i) values[i] = static_cast<std::int64_t>(value[i]);
  EnumeratorValues(name, values, static_cast<std::int64_t>(first), static_cast<std::int64_t>(last));
  if (!restoring() || !ok()) return;
  for (std::size_t i = 0; i < value.size(); ++i) value[i] = static_cast<Enum>(values[i]);
}

template <class Pod>
void StateArchive::Field(std::string_view name, std::vector<Pod>& value) {
  static_assert(std::is_trivially_copyable_v<Pod> && !std::is_enum_v<Pod>,
                "stored as raw bytes: only plain structs of numbers");
  Array(Type::kBytes, name, value.data(), value.size(), sizeof(Pod), 1);
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SNAPSHOT_STATE_ARCHIVE_H_
