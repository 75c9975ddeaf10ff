#!/usr/bin/env bash
# The README's test command: installs and builds if needed, then runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
cd build
ctest --output-on-failure -j "$(nproc)" --timeout 1200
