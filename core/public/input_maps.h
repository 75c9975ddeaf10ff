#ifndef NUPMPC_CORE_PUBLIC_INPUT_MAPS_H_
#define NUPMPC_CORE_PUBLIC_INPUT_MAPS_H_

// Helpers that rewrite a problem's inputs: priors on input differences
// (AugmentWithInputDifferences) and multi-level inputs (ExpandMultiLevelInputs).
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/model/input_differences.h"  // IWYU pragma: export
#include "core/model/multilevel_inputs.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_INPUT_MAPS_H_
