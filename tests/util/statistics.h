#ifndef NUPMPC_TESTS_UTIL_STATISTICS_H_
#define NUPMPC_TESTS_UTIL_STATISTICS_H_

#include <algorithm>
#include <vector>

namespace nupmpc::testing {

// The median of `v` (the mean of the middle two for an even count); 0 for none.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 == 1 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_STATISTICS_H_
