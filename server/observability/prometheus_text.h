#ifndef NUPMPC_SERVER_OBSERVABILITY_PROMETHEUS_TEXT_H_
#define NUPMPC_SERVER_OBSERVABILITY_PROMETHEUS_TEXT_H_

// The Prometheus text exposition format (version 0.0.4), written by hand because
// Prometheus' C++ client is not a Debian 12 package: families of samples, each family
// introduced by its # HELP and # TYPE lines, label values escaped, histograms as cumulative
// _bucket{le="..."} samples with _sum and _count.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/string_view.h"

namespace nupmpc::server {

using PrometheusLabels = std::vector<std::pair<std::string, std::string>>;

class PrometheusText {
 public:
  // # HELP and # TYPE ("counter", "gauge", "histogram"); write each family once, followed
  // by all of its samples.
  void Family(absl::string_view name, absl::string_view type, absl::string_view help);
  void Sample(absl::string_view name, const PrometheusLabels& labels, double value);
  // `counts[i]` observations fell in (upper_bounds[i-1], upper_bounds[i]]; the last count is
  // those above every bound (+Inf). Written cumulatively, as the format wants.
  void Histogram(absl::string_view name, const PrometheusLabels& labels, const std::vector<double>& upper_bounds,
                 const std::vector<std::uint64_t>& counts, double sum);
  const std::string& text() const { return text_; }

 private:
  std::string text_;
};

// A label value with \, " and newline escaped.
std::string EscapePrometheusLabelValue(absl::string_view value);
// A sample value: +Inf, -Inf, NaN, integers without exponent, others to 17 significant digits.
std::string FormatPrometheusValue(double value);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_PROMETHEUS_TEXT_H_
