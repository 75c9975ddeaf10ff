#!/usr/bin/env bash
# Installs every build and test dependency of nupmpc from Debian 12 packages, saying what
# it does (one line per step). Idempotent; run as root (or with sudo available).
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git python3
  libeigen3-dev libabsl-dev
  libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc
  libspdlog-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  liblbfgs-dev coinor-libipopt-dev
  clang libclang-rt-14-dev
  haproxy python3-yaml python3-kubernetes yamllint libcpp-httplib-dev
  python3-grpcio python3-protobuf python3-numpy python3-matplotlib python3-pytest
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
export DEBIAN_FRONTEND=noninteractive
echo "install-deps: ${#missing[@]} Debian packages to install: ${missing[*]}"
echo "install-deps: apt-get update"
"${sudo_cmd[@]}" apt-get update -qq
echo "install-deps: downloading and installing them with their dependencies (a few minutes on a fresh machine)"
requested=$(printf '%s\n' "${missing[@]}" | sed 's/[+.]/\\&/g' | paste -sd'|')  # as an ERE
"${sudo_cmd[@]}" apt-get install -y --no-install-recommends "${missing[@]}" 2>&1 |
  { grep -E "^(Need to get|Setting up ($requested)(:amd64)? )" || true; } |
  sed -e 's/^/install-deps: /' -e 's/ \.\.\.$//'
# The pipe above hides apt-get's exit status: check the result instead.
for p in "${missing[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
    { echo "install-deps: $p failed to install (run: apt-get install $p)" >&2; exit 1; }
done
echo "install-deps: done"
