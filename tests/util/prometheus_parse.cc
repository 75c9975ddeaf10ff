#include "tests/util/prometheus_parse.h"

#include <cmath>
#include <limits>
#include <regex>
#include <sstream>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace nupmpc::testing {
namespace {

const std::regex kName("[a-zA-Z_:][a-zA-Z0-9_:]*");
// name, optional {label="value",...}, value
const std::regex kSample(
    R"re(([a-zA-Z_:][a-zA-Z0-9_:]*)(\{((?:[a-zA-Z_][a-zA-Z0-9_]*="(?:[^"\\]|\\.)*",?)*)\})? (\S+))re");
const std::regex kLabel(R"re(([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\]|\\.)*)")re");

absl::StatusOr<double> ParseValue(const std::string& s) {
  if (s == "+Inf") return std::numeric_limits<double>::infinity();
  if (s == "-Inf") return -std::numeric_limits<double>::infinity();
  if (s == "NaN") return std::numeric_limits<double>::quiet_NaN();
  double v = 0.0;
  if (!absl::SimpleAtod(s, &v)) return absl::InvalidArgumentError(absl::StrCat("value \"", s, "\""));
  return v;
}

// The family a sample belongs to: histograms own name_bucket, name_sum, name_count.
std::string FamilyOf(const std::string& name, const std::map<std::string, std::string>& types) {
  for (const char* suffix : {"_bucket", "_sum", "_count"}) {
    const std::string s(suffix);
    if (name.size() > s.size() && name.compare(name.size() - s.size(), s.size(), s) == 0) {
      const std::string base = name.substr(0, name.size() - s.size());
      const auto it = types.find(base);
      if (it != types.end() && it->second == "histogram") return base;
    }
  }
  return name;
}

}  // namespace

double ParsedMetrics::at(const std::string& key) const {
  const auto it = samples.find(key);
  return it == samples.end() ? 0.0 : it->second;
}

absl::StatusOr<ParsedMetrics> ParsePrometheusText(const std::string& text) {
  ParsedMetrics out;
  std::map<std::string, std::vector<std::pair<double, double>>> buckets;  // histogram series → (le, count)
  std::istringstream lines(text);
  std::string line;
  int number = 0;
  while (std::getline(lines, line)) {
    ++number;
    const auto error = [&](const std::string& what) {
      return absl::InvalidArgumentError(absl::StrCat("line ", number, ": ", what, ": ", line));
    };
    if (line.empty()) continue;
    if (line.rfind("# HELP ", 0) == 0) continue;
    if (line.rfind("# TYPE ", 0) == 0) {
      std::istringstream words(line.substr(7));
      std::string name, type;
      words >> name >> type;
      if (!std::regex_match(name, kName)) return error("metric name");
      if (type != "counter" && type != "gauge" && type != "histogram") return error("type");
      if (!out.types.emplace(name, type).second) return error("family declared twice");
      continue;
    }
    if (line[0] == '#') continue;
    std::smatch m;
    if (!std::regex_match(line, m, kSample)) return error("not a sample");
    const std::string name = m[1];
    const std::string family = FamilyOf(name, out.types);
    if (out.types.count(family) == 0) return error("sample before its # TYPE");
    absl::StatusOr<double> value = ParseValue(m[4]);
    if (!value.ok()) return error(std::string(value.status().message()));
    const std::string labels = m[3];
    const std::string key = labels.empty() ? name : absl::StrCat(name, "{", labels, "}");
    if (!out.samples.emplace(key, *value).second) return error("sample repeated");
    if (name == family + "_bucket") {
      std::string series;
      double le = std::numeric_limits<double>::quiet_NaN();
      for (std::sregex_iterator it(labels.begin(), labels.end(), kLabel), end; it != end; ++it) {
        if ((*it)[1] == "le") {
          absl::StatusOr<double> bound = ParseValue((*it)[2]);
          if (!bound.ok()) return error("le");
          le = *bound;
        } else {
          absl::StrAppend(&series, (*it)[0].str(), ",");
        }
      }
      if (std::isnan(le)) return error("bucket without le");
      buckets[family + "{" + series + "}"].emplace_back(le, *value);
    }
  }
  for (const auto& [series, points] : buckets) {
    for (std::size_t i = 1; i < points.size(); ++i) {
      if (!(points[i].first > points[i - 1].first) || points[i].second < points[i - 1].second) {
        return absl::InvalidArgumentError(absl::StrCat(series, ": buckets not increasing and cumulative"));
      }
    }
    if (points.empty() || !std::isinf(points.back().first)) {
      return absl::InvalidArgumentError(absl::StrCat(series, ": no +Inf bucket"));
    }
  }
  // Each histogram's +Inf bucket is its _count (series without labels: the tests' case).
  for (const auto& [family, type] : out.types) {
    if (type != "histogram") continue;
    const auto inf = out.samples.find(family + "_bucket{le=\"+Inf\"}");
    const auto count = out.samples.find(family + "_count");
    if (inf != out.samples.end() && count != out.samples.end() && inf->second != count->second) {
      return absl::InvalidArgumentError(
          absl::StrCat(family, ": +Inf bucket ", inf->second, " but _count ", count->second));
    }
  }
  return out;
}

}  // namespace nupmpc::testing
