#ifndef NUPMPC_CORE_PUBLIC_SESSION_H_
#define NUPMPC_CORE_PUBLIC_SESSION_H_

// A plain core session (core::Session): create from a Problem, set x[0], solve, shift
// the warm start; with its pass-level trace and footprint, for embedding and benchmarks.
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/session/session.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_SESSION_H_
