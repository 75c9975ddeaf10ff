#ifndef NUPMPC_CORE_PLATFORM_CPU_BASELINE_H_
#define NUPMPC_CORE_PLATFORM_CPU_BASELINE_H_

// The x86-64 instruction-set baseline of this build (CMake: NUPMPC_CPU_BASELINE).
//
// Every translation unit of the project is compiled for one baseline, and no prebuilt
// library that instantiates Eigen is linked (tests/build/eigen_odr_check.py checks both):
// Eigen's inline functions are compiled differently for each vector width (16-, 32- or
// 64-byte alignment, different allocators), and the linker keeps only one copy of each,
// so two settings in one program free memory with the wrong allocator.
//
// Every executable also links cpu_baseline_guard.cc, which refuses to start, with a
// message naming the missing extensions, on a CPU that lacks one this build uses (instead
// of dying of SIGILL somewhere later).

namespace nupmpc::platform {

// The CMake setting, e.g. "x86-64-v3" or "native".
extern const char kBuildCpuBaseline[];
// The vector and bit-manipulation extensions the compiler could use, space-separated in
// __builtin_cpu_supports spelling (e.g. "sse3 ssse3 sse4.1 sse4.2 popcnt avx avx2 fma bmi bmi2").
extern const char kBuildCpuFeatures[];

}  // namespace nupmpc::platform

#endif  // NUPMPC_CORE_PLATFORM_CPU_BASELINE_H_
