#ifndef NUPMPC_CORE_SNAPSHOT_STATE_ARCHIVE_H_
#define NUPMPC_CORE_SNAPSHOT_STATE_ARCHIVE_H_

// A session's state as bytes and back, for snapshots (a session that survives a restart or
// moves to another process). Every class with state writes ONE function that both saves
// and restores it, so the two directions cannot drift:
//
//   void Iffbdd::PersistState(StateArchive& archive) {
//     archive.Field("nup", nup_);
//     archive.Field("gamma", gamma_);
//     archive.Flag("has_duals", has_duals_);
//   }
//
// Restoring goes into a session rebuilt from the same creation spec, so every field
// already has its shape: a restore requires the stored shape to equal the current one
// (`Field`), or to stay within a bound the class states (`ResizableField`). Records are
// matched by name and type in order; the first mismatch (another spec, another version,
// truncated or altered bytes) stops the archive with INVALID_ARGUMENT naming the field,
// and every later call is a no-op. Bytes are little-endian IEEE doubles (x86-64 only).
//
// Nothing here decides what is worth saving: that is each class's PersistState.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"

namespace nupmpc::core {

class StateArchive {
 public:
  virtual ~StateArchive() = default;
  virtual bool restoring() const = 0;

  // Scalars.
  virtual void Number(std::string_view name, double& value) = 0;
  virtual void Integer(std::string_view name, std::int64_t& value) = 0;
  void Integer(std::string_view name, int& value);
  virtual void Flag(std::string_view name, bool& value) = 0;
  // An enum stored as its underlying integer; a restore refuses values outside
  // [0, count): `count` is the number of enumerators.
  template <class Enum>
  void Enumerator(std::string_view name, Enum& value, int count);

  // Fixed-shape arrays: on restore the stored shape must equal the current one.
  virtual void Field(std::string_view name, Eigen::VectorXd& value) = 0;
  virtual void Field(std::string_view name, Eigen::MatrixXd& value) = 0;
  virtual void Field(std::string_view name, std::vector<double>& value) = 0;
  virtual void Field(std::string_view name, std::vector<int>& value) = 0;
  // Plain structs of doubles (ScalarFactor, ...): stored as their bytes with sizeof(T).
  template <class Pod>
  void Field(std::string_view name, std::vector<Pod>& value);
  // Vectors of enums (Region, ...), each checked as in Enumerator.
  template <class Enum>
  void EnumeratorField(std::string_view name, std::vector<Enum>& value, int count);

  // Arrays whose length a restore may change, within [0, max_size] elements.
  virtual void ResizableField(std::string_view name, Eigen::VectorXd& value, std::size_t max_size) = 0;

  // Groups the fields of one part under a name (for error messages: "iffbdd.gamma").
  virtual void BeginSection(std::string_view name) = 0;
  virtual void EndSection() = 0;

  // A restore that has read everything checks that nothing is left over.
  virtual absl::Status status() const = 0;

 protected:
  // Raw elements of a POD vector: `element_size` bytes each; fixed shape.
  virtual void Bytes(std::string_view name, void* data, std::size_t count, std::size_t element_size) = 0;
  // Stops the archive (restore) with INVALID_ARGUMENT "<section>.<name>: <why>".
  virtual void Fail(std::string_view name, std::string_view why) = 0;
};

// Writes to `out` (appended).
class StateWriter final : public StateArchive { /* state_archive.cc */ };
// Reads from `bytes` (not owned; must outlive the reader). status() after the last field
// also fails when bytes are left over.
class StateReader final : public StateArchive { /* state_archive.cc */ };

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SNAPSHOT_STATE_ARCHIVE_H_
