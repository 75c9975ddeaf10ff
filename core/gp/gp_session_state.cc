// GP session snapshots: the step's data a client sets (the past window and the reference,
// restored through Apply() like any update), and what the next SCP solve starts from (the
// warm nominal inputs and the subproblem session's carried state). The factorised GP is
// the creation spec's (immutable, possibly shared): it is not part of a snapshot.

#include <limits>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/gp/gp_mpc_session.h"
#include "core/gp/lingp_scp.h"
#include "core/snapshot/state_archive.h"
#include "core/util/status_macros.h"

namespace nupmpc::gp {
namespace {

// A nested snapshot's refusal, named by its place in the outer one.
absl::Status Nested(const char* part, const absl::Status& status) {
  if (status.ok() || status.code() != absl::StatusCode::kInvalidArgument) return status;
  return absl::InvalidArgumentError(absl::StrCat(part, ": ", status.message()));
}

}  // namespace

absl::Status LinGpScp::SaveState(std::string* out) {
  std::string inner;
  NUPMPC_RETURN_IF_ERROR(session_->SaveState(&inner));
  core::StateWriter writer(out);
  PersistState(writer, inner);
  return writer.status();
}

absl::Status LinGpScp::RestoreState(std::string_view bytes) {
  std::string inner;
  core::StateReader reader(bytes);
  PersistState(reader, inner);
  NUPMPC_RETURN_IF_ERROR(reader.status());
  return Nested("scp.subproblem", session_->RestoreState(inner));
}

void LinGpScp::PersistState(core::StateArchive& archive, std::string& inner) {
  archive.BeginSection("scp");
  archive.Flag("has_warm", has_warm_);
  // The warm plan's inputs (its trajectory is simulated again from them at every solve).
  archive.Field("nominal_u", nominal_u_);
  // Bounded by the input itself (the reader checks what is left before copying).
  archive.Blob("subproblem", inner, std::numeric_limits<std::size_t>::max());
  archive.EndSection();
}

absl::Status GpMpcSession::SaveState(std::string* out) {
  std::string scp;
  NUPMPC_RETURN_IF_ERROR(scp_->SaveState(&scp));
  Eigen::VectorXd window = shape_.initial_mean, reference = reference_;
  core::StateWriter writer(out);
  PersistState(writer, scp, window, reference);
  return writer.status();
}

absl::Status GpMpcSession::RestoreState(std::string_view bytes) {
  std::string scp;
  Eigen::VectorXd window = shape_.initial_mean, reference = reference_;
  core::StateReader reader(bytes);
  PersistState(reader, scp, window, reference);
  NUPMPC_RETURN_IF_ERROR(reader.status());
  core::StepUpdate values;
  values.state = window;
  values.reference = reference;
  NUPMPC_RETURN_IF_ERROR(Nested("gp_session", Apply(values)));
  return Nested("gp_session", scp_->RestoreState(scp));
}

void GpMpcSession::PersistState(core::StateArchive& archive, std::string& scp, Eigen::VectorXd& window,
                                Eigen::VectorXd& reference) {
  archive.BeginSection("gp_session");
  archive.Field("window", window);
  archive.Field("reference", reference);
  archive.Flag("solved", solved_);
  archive.Blob("scp", scp, std::numeric_limits<std::size_t>::max());
  archive.EndSection();
}

}  // namespace nupmpc::gp
