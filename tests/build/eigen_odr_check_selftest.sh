#!/usr/bin/env bash
# The ODR check must see what it is there to see: a prebuilt archive that instantiates
# Eigen (compiled here for plain x86-64, as a distribution's library would be) is a
# finding, and liblbfgs (C, no Eigen) is not.
#   eigen_odr_check_selftest.sh CXX EIGEN_INCLUDE_DIR
set -euo pipefail
cxx=$1
eigen=$2
check="$(dirname "$0")/eigen_odr_check.py"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat >"$work/prebuilt.cc" <<'CC'
#include "Eigen/Core"
Eigen::MatrixXd Twice(const Eigen::MatrixXd& m) { return 2.0 * m; }
CC
"$cxx" -std=c++20 -O2 -march=x86-64 -I"$eigen" -c "$work/prebuilt.cc" -o "$work/prebuilt.o"
ar rcs "$work/libprebuilt.a" "$work/prebuilt.o"
if python3 "$check" --archive "$work/libprebuilt.a"; then
  echo "FAIL: an archive with Eigen code passed the check" >&2
  exit 1
fi
lbfgs=$(pkg-config --variable=libdir liblbfgs 2>/dev/null || true)
lbfgs=${lbfgs:-/usr/lib/x86_64-linux-gnu}/liblbfgs.a
[ -f "$lbfgs" ] || lbfgs=$(g++ -print-file-name=liblbfgs.a)
python3 "$check" --archive "$lbfgs"
echo "ok: the check tells an archive with Eigen code from one without"
