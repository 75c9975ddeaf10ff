#ifndef NUPMPC_CORE_PUBLIC_NONLINEAR_H_
#define NUPMPC_CORE_PUBLIC_NONLINEAR_H_

// Nonlinear problems as sequences of linearised ones: a user's nonlinear model
// (NonlinearModel, TrustRegion), keep-out regions on a linear plant (KeepOut, KeepOutSession),
// and the SequentialSolver that runs either.
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/nonlinear/keep_out.h"           // IWYU pragma: export
#include "core/nonlinear/keep_out_session.h"   // IWYU pragma: export
#include "core/nonlinear/nonlinear_model.h"    // IWYU pragma: export
#include "core/nonlinear/sequential_solver.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_NONLINEAR_H_
