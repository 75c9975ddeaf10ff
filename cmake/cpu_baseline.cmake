# NUPMPC_CPU_BASELINE: the x86-64 instructions every target may use, one setting for the
# whole build (see core/platform/cpu_baseline.h for why it must be one).
#   x86-64, x86-64-v2, x86-64-v3 (AVX2, FMA), x86-64-v4 (AVX-512): the psABI levels,
#     for binaries that run on every CPU of that level;
#   native: tuned for the build machine, for binaries that stay on it.
# Default: x86-64-v3 where the build machine has it (so the build runs where it was
# built and on every x86-64 server since about 2015), else the highest level it has.
# The choice is stored in the cache: later builds keep it until it is set again.
set(_nupmpc_baselines x86-64 x86-64-v2 x86-64-v3 x86-64-v4 native)

if(NOT DEFINED CACHE{NUPMPC_CPU_BASELINE})
  set(_nupmpc_default x86-64)
  foreach(level x86-64-v2 x86-64-v3)
    # Which levels this machine runs (GCC names the psABI levels in __builtin_cpu_supports).
    try_run(_runs _compiles SOURCE_FROM_CONTENT probe.cc
      "int main() { __builtin_cpu_init(); return __builtin_cpu_supports(\"${level}\") ? 0 : 1; }"
      COMPILE_OUTPUT_VARIABLE _probe_output)
    if(_compiles AND _runs EQUAL 0)
      set(_nupmpc_default ${level})
    endif()
  endforeach()
  if(NOT _nupmpc_default STREQUAL "x86-64-v3")
    message(STATUS "This machine lacks x86-64-v3 (AVX2, FMA): NUPMPC_CPU_BASELINE defaults to ${_nupmpc_default}")
  endif()
  set(NUPMPC_CPU_BASELINE ${_nupmpc_default} CACHE STRING "x86-64 instruction baseline: ${_nupmpc_baselines}")
  set_property(CACHE NUPMPC_CPU_BASELINE PROPERTY STRINGS ${_nupmpc_baselines})
endif()

if(NOT NUPMPC_CPU_BASELINE IN_LIST _nupmpc_baselines)
  message(FATAL_ERROR "NUPMPC_CPU_BASELINE=${NUPMPC_CPU_BASELINE}: must be one of ${_nupmpc_baselines}")
endif()
if(NUPMPC_CPU_BASELINE STREQUAL "native")
  set(NUPMPC_CPU_FLAGS -march=native)
else()
  # -mtune=generic: the same code whatever machine builds it.
  set(NUPMPC_CPU_FLAGS -march=${NUPMPC_CPU_BASELINE} -mtune=generic)
endif()
# Whether the baseline's instructions include AVX-512 (x86-64-v4, or native on such a CPU):
# compiler workarounds below depend on it. Cached per baseline, as the baseline may change.
include(CheckCXXSourceCompiles)
string(REPLACE ";" " " CMAKE_REQUIRED_FLAGS "${NUPMPC_CPU_FLAGS}")
string(MAKE_C_IDENTIFIER "NUPMPC_AVX512_${NUPMPC_CPU_BASELINE}" _avx512_result)
check_cxx_source_compiles("#ifndef __AVX512F__\n#error no AVX-512\n#endif\nint main() {}" ${_avx512_result})
unset(CMAKE_REQUIRED_FLAGS)
if(${_avx512_result})
  set(NUPMPC_CPU_BASELINE_AVX512 ON)
else()
  set(NUPMPC_CPU_BASELINE_AVX512 OFF)
endif()
message(STATUS "CPU baseline: ${NUPMPC_CPU_BASELINE} (${NUPMPC_CPU_FLAGS}), AVX-512: ${NUPMPC_CPU_BASELINE_AVX512}")
