// Linked into every executable (CMake: nupmpc_flags) and compiled for the plain x86-64
// baseline whatever NUPMPC_CPU_BASELINE says, so it runs on any x86-64 CPU. C library
// only: no Eigen, no inline C++ library code that a copy compiled with wider vectors
// could replace at link time.

#include <unistd.h>

#include <cstring>

#include "core/platform/cpu_baseline.h"

namespace nupmpc::platform {
namespace {

bool CpuSupports(const char* feature) {
  // __builtin_cpu_supports takes only string literals.
  struct Known {
    const char* name;
    bool present;
  };
  const Known known[] = {
      {"sse3", __builtin_cpu_supports("sse3") != 0},         {"ssse3", __builtin_cpu_supports("ssse3") != 0},
      {"sse4.1", __builtin_cpu_supports("sse4.1") != 0},     {"sse4.2", __builtin_cpu_supports("sse4.2") != 0},
      {"popcnt", __builtin_cpu_supports("popcnt") != 0},     {"avx", __builtin_cpu_supports("avx") != 0},
      {"avx2", __builtin_cpu_supports("avx2") != 0},         {"fma", __builtin_cpu_supports("fma") != 0},
      {"bmi", __builtin_cpu_supports("bmi") != 0},           {"bmi2", __builtin_cpu_supports("bmi2") != 0},
      {"avx512f", __builtin_cpu_supports("avx512f") != 0},   {"avx512cd", __builtin_cpu_supports("avx512cd") != 0},
      {"avx512bw", __builtin_cpu_supports("avx512bw") != 0}, {"avx512dq", __builtin_cpu_supports("avx512dq") != 0},
      {"avx512vl", __builtin_cpu_supports("avx512vl") != 0},
  };
  for (const Known& k : known) {
    if (std::strcmp(k.name, feature) == 0) return k.present;
  }
  return false;  // cpu_baseline.cc lists only names of the table above
}

void Write(const char* text) { (void)!write(STDERR_FILENO, text, std::strlen(text)); }

// Priority 101: before the program's own static initialisers, which may already use the
// extensions.
__attribute__((constructor(101))) void RefuseCpuWithoutBuildBaseline() {
  __builtin_cpu_init();
  char missing[256] = "";
  char feature[32];
  for (const char* p = kBuildCpuFeatures; *p != '\0';) {
    while (*p == ' ') ++p;
    const std::size_t length = std::strcspn(p, " ");
    if (length == 0 || length >= sizeof feature) break;
    std::memcpy(feature, p, length);
    feature[length] = '\0';
    p += length;
    if (!CpuSupports(feature)) {
      std::strncat(missing, " ", sizeof missing - std::strlen(missing) - 1);
      std::strncat(missing, feature, sizeof missing - std::strlen(missing) - 1);
    }
  }
  if (missing[0] == '\0') return;
  Write("nupmpc: this build uses CPU extensions this machine lacks:");
  Write(missing);
  Write(" (NUPMPC_CPU_BASELINE=");
  Write(kBuildCpuBaseline);
  Write("). Rebuild for this CPU, e.g. NUPMPC_CPU_BASELINE=x86-64-v2 deploy/build.sh\n");
  _exit(78);  // EX_CONFIG
}

}  // namespace
}  // namespace nupmpc::platform
