#include "core/platform/cpu_baseline.h"

// Compiled with the project's flags, so the predefined macros below are the extensions
// the whole build may use. Constant data only: cpu_baseline_guard.cc reads it before any
// code compiled with these flags runs.

namespace nupmpc::platform {

const char kBuildCpuBaseline[] = NUPMPC_CPU_BASELINE;

const char kBuildCpuFeatures[] =
    ""
#ifdef __SSE3__
    " sse3"
#endif
#ifdef __SSSE3__
    " ssse3"
#endif
#ifdef __SSE4_1__
    " sse4.1"
#endif
#ifdef __SSE4_2__
    " sse4.2"
#endif
#ifdef __POPCNT__
    " popcnt"
#endif
#ifdef __AVX__
    " avx"
#endif
#ifdef __AVX2__
    " avx2"
#endif
#ifdef __FMA__
    " fma"
#endif
#ifdef __BMI__
    " bmi"
#endif
#ifdef __BMI2__
    " bmi2"
#endif
#ifdef __AVX512F__
    " avx512f"
#endif
#ifdef __AVX512CD__
    " avx512cd"
#endif
#ifdef __AVX512BW__
    " avx512bw"
#endif
#ifdef __AVX512DQ__
    " avx512dq"
#endif
#ifdef __AVX512VL__
    " avx512vl"
#endif
    ;

}  // namespace nupmpc::platform
