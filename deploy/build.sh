#!/usr/bin/env bash
# Installs dependencies (if missing) and builds everything into build/ (executables in build/bin/).
# NUPMPC_NATIVE=OFF gives a portable build (containers); the default tunes for this machine.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DNUPMPC_NATIVE="${NUPMPC_NATIVE:-ON}" >/dev/null
cmake --build build -j "$(nproc)"
