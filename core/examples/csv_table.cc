#include "core/examples/csv_table.h"

#include <algorithm>
#include <fstream>

#include "absl/strings/str_cat.h"

namespace nupmpc::examples {

absl::Status WriteCsv(const std::string& path, const CsvColumns& columns) {
  std::ofstream out(path);
  if (!out) return absl::UnavailableError(absl::StrCat(path, ": cannot open for writing"));
  Eigen::Index rows = 0;
  for (std::size_t c = 0; c < columns.size(); ++c) {
    out << (c ? "," : "") << columns[c].first;
    rows = std::max(rows, columns[c].second.size());
  }
  out << "\n";
  out.precision(10);
  for (Eigen::Index r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < columns.size(); ++c) {
      if (c) out << ",";
      if (r < columns[c].second.size()) out << columns[c].second(r);
    }
    out << "\n";
  }
  if (!out) return absl::UnavailableError(absl::StrCat(path, ": write failed"));
  return absl::OkStatus();
}

}  // namespace nupmpc::examples
