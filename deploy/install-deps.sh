#!/usr/bin/env bash
# Installs every build and test dependency of nupmpc from Debian 12 packages, saying what
# it does (one line per step), then checks that every program the build, the tests and
# their scripts call is there. Idempotent; run as root (or with sudo available). Packages
# are installed without their recommendations, so a program the suite calls is listed here
# by its own package even where another package recommends it.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git python3 ca-certificates
  libeigen3-dev libabsl-dev
  libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc
  libspdlog-dev nlohmann-json3-dev
  libssl-dev    # libcrypto: the session snapshots' integrity tags (server/snapshots/)
  libgtest-dev libgmock-dev libbenchmark-dev
  liblbfgs-dev coinor-libipopt-dev
  clang libclang-rt-14-dev
  clang-format clang-tidy  # the tree's style and lint (.clang-format, .clang-tidy; tests/build/)
  llvm-14       # llvm-symbolizer: sanitizer stacks are unreadable without it (clang only recommends it)
  openssl       # the TLS tests' certificates (tests/util/test_pki.cc, the Python client's tests)
  prometheus    # promtool: Prometheus' own check of /metrics (metrics_endpoint_test)
  haproxy python3-yaml python3-kubernetes yamllint libcpp-httplib-dev
  nftables iproute2  # nft, ip: the quiet faults' partitions in namespaces (tests/soak/quiet_faults.py)
  python3-grpcio python3-protobuf python3-numpy python3-matplotlib python3-pytest
  mypy          # the Python client's type check (PythonClient.MypyStrictIsClean)
)
# Programs the build, the tests and their scripts call (beyond a minimal Debian's own), and
# the package each comes from: checked after every run, so a package that no longer brings
# one is reported here rather than as a test that failed or, worse, did not run.
programs=(
  cmake:cmake ninja:ninja-build g++:build-essential pkg-config:pkg-config git:git python3:python3
  protoc:protobuf-compiler grpc_cpp_plugin:protobuf-compiler-grpc grpc_python_plugin:protobuf-compiler-grpc
  clang++:clang llvm-symbolizer-14:llvm-14 nm:binutils c++filt:binutils
  clang-format-14:clang-format clang-tidy-14:clang-tidy
  openssl:openssl promtool:prometheus haproxy:haproxy yamllint:yamllint nft:nftables ip:iproute2
  mypy:mypy
)

check_programs() {
  local missing=() entry
  for entry in "${programs[@]}"; do
    command -v "${entry%%:*}" >/dev/null || missing+=("${entry%%:*} (package ${entry#*:})")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    printf 'install-deps: missing after installing: %s\n' "${missing[@]}" >&2
    exit 1
  fi
}

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  check_programs
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
check_programs
echo "install-deps: done"
