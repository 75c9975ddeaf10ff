#include "loadtest/bench/instance_result.h"

#include <algorithm>

#include "absl/strings/str_format.h"

namespace nupmpc::bench {

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::string Num(double v) { return std::isfinite(v) ? absl::StrFormat("%.17g", v) : "null"; }

}  // namespace nupmpc::bench
