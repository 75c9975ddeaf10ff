#ifndef NUPMPC_CORE_EXAMPLES_CSV_TABLE_H_
#define NUPMPC_CORE_EXAMPLES_CSV_TABLE_H_

// Writes the examples' trajectories for plot_examples.py: one header line, then one row
// per index; shorter columns leave their cells empty.

#include <string>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"

namespace nupmpc::examples {

using CsvColumns = std::vector<std::pair<std::string, Eigen::VectorXd>>;

absl::Status WriteCsv(const std::string& path, const CsvColumns& columns);

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_CSV_TABLE_H_
