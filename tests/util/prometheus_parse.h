#ifndef NUPMPC_TESTS_UTIL_PROMETHEUS_PARSE_H_
#define NUPMPC_TESTS_UTIL_PROMETHEUS_PARSE_H_

// A strict reader of the Prometheus text exposition format (0.0.4), independent of the
// server's writer: the tests parse /metrics with it. It refuses what Prometheus would:
// a sample before its family's # TYPE, a family declared twice, an unknown type, a
// malformed name, label set or value, a histogram whose buckets are not cumulative or
// whose +Inf bucket differs from _count.

#include <map>
#include <string>

#include "absl/status/statusor.h"

namespace nupmpc::testing {

struct ParsedMetrics {
  std::map<std::string, std::string> types;  // family → counter, gauge, histogram
  // "name{a="x",b="y"}" (labels as written) → value; a sample without labels is "name".
  std::map<std::string, double> samples;
  double at(const std::string& key) const;  // 0 for a missing sample
};

absl::StatusOr<ParsedMetrics> ParsePrometheusText(const std::string& text);

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_PROMETHEUS_PARSE_H_
