#ifndef NUPMPC_CORE_PUBLIC_MODEL_UPDATE_H_
#define NUPMPC_CORE_PUBLIC_MODEL_UPDATE_H_

// The model changes a step may carry (ModelChanges) and what storing them costs.
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/session/model_update.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_MODEL_UPDATE_H_
