#include "server/observability/prometheus_text.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace nupmpc::server {

std::string EscapePrometheusLabelValue(absl::string_view value) {
  std::string out;
  out.reserve(value.size());
  for (const char c : value) {
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '"') {
      out += "\\\"";
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out;
}

std::string FormatPrometheusValue(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
  // Counts stay exact and readable; 2^53 is where doubles stop being exact integers.
  if (value == std::floor(value) && std::abs(value) < 9007199254740992.0) return absl::StrFormat("%.0f", value);
  return absl::StrFormat("%.17g", value);
}

namespace {

void AppendLabels(const PrometheusLabels& labels, std::string* out) {
  if (labels.empty()) return;
  *out += '{';
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (i > 0) *out += ',';
    absl::StrAppend(out, labels[i].first, "=\"", EscapePrometheusLabelValue(labels[i].second), "\"");
  }
  *out += '}';
}

}  // namespace

void PrometheusText::Family(absl::string_view name, absl::string_view type, absl::string_view help) {
  // HELP text escapes only backslash and newline.
  std::string escaped;
  for (const char c : help) {
    if (c == '\\') {
      escaped += "\\\\";
    } else if (c == '\n') {
      escaped += "\\n";
    } else {
      escaped += c;
    }
  }
  absl::StrAppend(&text_, "# HELP ", name, " ", escaped, "\n# TYPE ", name, " ", type, "\n");
}

void PrometheusText::Sample(absl::string_view name, const PrometheusLabels& labels, double value) {
  text_.append(name.data(), name.size());
  AppendLabels(labels, &text_);
  absl::StrAppend(&text_, " ", FormatPrometheusValue(value), "\n");
}

void PrometheusText::Histogram(absl::string_view name, const PrometheusLabels& labels,
                               const std::vector<double>& upper_bounds, const std::vector<std::uint64_t>& counts,
                               double sum) {
  const std::string bucket = absl::StrCat(name, "_bucket");
  std::uint64_t cumulative = 0;
  for (std::size_t i = 0; i <= upper_bounds.size(); ++i) {
    cumulative += i < counts.size() ? counts[i] : 0;
    PrometheusLabels with_le = labels;
    with_le.emplace_back("le", i < upper_bounds.size() ? FormatPrometheusValue(upper_bounds[i]) : "+Inf");
    Sample(bucket, with_le, static_cast<double>(cumulative));
  }
  Sample(absl::StrCat(name, "_sum"), labels, sum);
  Sample(absl::StrCat(name, "_count"), labels, static_cast<double>(cumulative));
}

}  // namespace nupmpc::server
