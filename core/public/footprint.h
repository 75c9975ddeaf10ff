#ifndef NUPMPC_CORE_PUBLIC_FOOTPRINT_H_
#define NUPMPC_CORE_PUBLIC_FOOTPRINT_H_

// What a session of a given problem costs before it is created: memory and flops per
// pass (EstimateFootprint), for admission by cost and memory budget.
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/session/footprint.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_FOOTPRINT_H_
