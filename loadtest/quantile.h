#ifndef NUPMPC_LOADTEST_QUANTILE_H_
#define NUPMPC_LOADTEST_QUANTILE_H_

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace nupmpc::loadtest {

// The q-quantile (0..1) of `values` by nearest rank (the smallest value with at least a
// fraction q of the values at or below it): every figure the load tests print is a value
// that was measured, never an interpolation. 0 when there are none.
inline double Quantile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(values.size())));
  const std::size_t index = std::clamp<std::size_t>(rank, 1, values.size()) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index), values.end());
  return values[index];
}

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_QUANTILE_H_
