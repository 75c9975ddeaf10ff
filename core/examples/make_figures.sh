#!/usr/bin/env bash
# Regenerates every example figure: builds, runs each nupmpc-example-* program (they
# print their measured figures and write CSV into DIR), then renders the PNGs.
# Usage: core/examples/make_figures.sh [DIR]   (default: figures/). Needs python3-matplotlib.
set -euo pipefail
cd "$(dirname "$0")/../.."
out="${1:-figures}"
deploy/build.sh
if ! /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
  echo "make_figures.sh: needs Debian's python3-matplotlib (apt-get install python3-matplotlib)" >&2
  exit 1
fi
for example in dac corridor flappy-bird obstacle-avoidance race-track; do
  echo "== nupmpc-example-${example}"
  "build/bin/nupmpc-example-${example}" --out_dir "${out}"
done
echo "== nupmpc-gp-bench (N = 200, 1500)"
build/bin/nupmpc-gp-bench --sizes 200,1500 --csv "${out}"
/usr/bin/python3 core/examples/plot_examples.py "${out}"
