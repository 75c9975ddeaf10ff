#ifndef NUPMPC_TESTS_UTIL_TEST_NAMES_H_
#define NUPMPC_TESTS_UTIL_TEST_NAMES_H_

// Short parts for the names of parameterised tests, so that ctest's names stay under 100
// characters (tests/check_test_names.cmake).

#include <cctype>
#include <string>

namespace nupmpc::testing {

// A benchmark instance's name without the dimension tags of the random instances, which
// all have the same ones: "random_outbox_M40_K20_L20_N1000_s1" → "random_outbox_s1".
// Other names are returned as they are. (No <regex>: no_allocation_test counts mallocs.)
inline std::string ShortInstanceName(const std::string& name) {
  for (std::size_t start = name.find("_M"); start != std::string::npos; start = name.find("_M", start + 1)) {
    std::size_t end = start;
    bool tags = true;
    for (const char* tag : {"_M", "_K", "_L", "_N"}) {
      if (name.compare(end, 2, tag) != 0) {
        tags = false;
        break;
      }
      const std::size_t digits = end += 2;
      while (end < name.size() && std::isdigit(static_cast<unsigned char>(name[end]))) ++end;
      if (end == digits) {
        tags = false;
        break;
      }
    }
    if (tags) return name.substr(0, start) + name.substr(end);
  }
  return name;
}

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_TEST_NAMES_H_
