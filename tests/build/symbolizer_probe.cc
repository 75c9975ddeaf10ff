// Compiled and run by deploy/sanitizer-symbolizer.sh before a sanitizer stage judges any
// report: its printed stack must name SymbolizerProbeFrame and this file, or the stage's
// reports could not be read (every frame "<null>") and the stage stops.
#include <sanitizer/common_interface_defs.h>

__attribute__((noinline)) void SymbolizerProbeFrame() { __sanitizer_print_stack_trace(); }

int main() {
  SymbolizerProbeFrame();
  return 0;
}
