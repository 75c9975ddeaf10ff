#!/usr/bin/env bash
# Soak and fault scenarios of the service, real processes on loopback:
#   deploy/soak.sh [MINUTES]           the soak: MINUTES (default 10, at least 4) of saturating mixed load
#                                      (tests/soak/soak.py), then every fault scenario
#                                      (tests/soak/faults.py) in its full form
#   NUPMPC_SOAK_FAULTS=0 deploy/soak.sh 10    the soak alone
# Builds what it runs first. The server, the load generator and the Python clients share
# this machine's cores: quote the figures with that. Exit 1 when any check fails.
set -euo pipefail
cd "$(dirname "$0")/.."
minutes="${1:-10}"
deploy/build.sh nupmpc-server nupmpc nupmpc-loadtest nupmpc-scaleout-probe silent_streams nupmpc_python
status=0
/usr/bin/python3 tests/soak/soak.py --seconds "$(awk "BEGIN { print $minutes * 60 }")" || status=1
if [ "${NUPMPC_SOAK_FAULTS:-1}" != 0 ]; then
  /usr/bin/python3 tests/soak/faults.py || status=1
fi
exit $status
