#!/usr/bin/env bash
# The README's main job: install dependencies, build, and run nupmpc-bench on every
# benchmark instance in ../shared/benchmarks (until the gRPC service exists).
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/build.sh
benchmarks="${NUPMPC_BENCHMARKS:-../shared/benchmarks}"
build/bin/nupmpc-bench --scaling "$benchmarks"/*.json
