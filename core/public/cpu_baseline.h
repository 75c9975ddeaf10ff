#ifndef NUPMPC_CORE_PUBLIC_CPU_BASELINE_H_
#define NUPMPC_CORE_PUBLIC_CPU_BASELINE_H_

// The instructions the build may use (its CPU baseline) and whether this machine has
// them.
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/platform/cpu_baseline.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_CPU_BASELINE_H_
