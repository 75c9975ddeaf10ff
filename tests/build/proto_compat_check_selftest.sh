#!/usr/bin/env bash
# The API check must see what it is there to see. On a copy of proto/ it passes; each
# breaking change planted in the copy's .proto text (one at a time) makes `check` fail,
# naming the element, and `update` refuses to write one into the baseline. A field retired by
# reserving its number and name, and an added field, pass as compatible but fail `check`
# until `update` has written them into the baseline; then `check` passes.
#   proto_compat_check_selftest.sh SOURCE_DIR
set -euo pipefail
src=$1
check="$(dirname "$0")/proto_compat_check.py"
python=/usr/bin/python3  # Debian's, for python3-protobuf
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# -L: a real copy even when proto/ (or a file in it) is a symlink, so that no planted edit
# can reach the source tree.
cp -rL "$src/proto" "$work/"
api=$work/proto/nupmpc/v1/nupmpc.proto
baseline=$work/proto/api_baseline/nupmpc_v1.txtpb
cp "$api" "$work/api.orig"
cp "$baseline" "$work/baseline.orig"

# expect MODE STATUS [TEXT]: runs the check in MODE on the copy and requires exit status
# STATUS and, if given, a line of output containing TEXT (shown).
expect() {
  local mode=$1 want=$2 text=${3:-} status=0
  "$python" "$check" "$mode" "$work" >"$work/out" 2>&1 || status=$?
  if [[ $status != "$want" ]] || { [[ -n $text ]] && ! grep -qF -- "$text" "$work/out"; }; then
    cat "$work/out"
    echo "FAIL: $mode exited with $status, expected $want and a line with: $text" >&2
    exit 1
  fi
  [[ -z $text ]] || grep -F -- "$text" "$work/out" | sed "s/^ */   $mode: /"
}

# plant TEXT SED_SCRIPT: edits the copy's .proto with SED_SCRIPT, expects `check` to fail
# naming TEXT, then restores the .proto.
plant() {
  local text=$1 script=$2
  sed -i "$script" "$api"
  if cmp -s "$api" "$work/api.orig"; then
    echo "FAIL: the edit for '$text' ($script) changed nothing" >&2
    exit 1
  fi
  echo "-- planted: $script"
  expect check 1 "$text"
  cp "$work/api.orig" "$api"
}

expect check 0
plant "nupmpc.v1.Step.state: field 1 removed" '/^  repeated double state = 1;/d'
plant "nupmpc.v1.Step.reference: field 7 removed" 's/^  repeated double reference = 7;/  reserved 7;/'
plant "nupmpc.v1.Step.max_iterations: field renumbered from 4 to 99" \
  's/^  uint32 max_iterations = 4;/  uint32 max_iterations = 99;/'
plant "nupmpc.v1.Step.state: field 1 retyped from repeated double to repeated float" \
  's/^  repeated double state = 1;/  repeated float state = 1;/'
plant "nupmpc.v1.Step.max_iterations: field 4 retyped from uint32 to optional uint32" \
  's/^  uint32 max_iterations = 4;/  optional uint32 max_iterations = 4;/'
plant "nupmpc.v1.Step.update: field 2 retyped from nupmpc.v1.PriorUpdate to nupmpc.v1.ModelUpdate" \
  's/^  PriorUpdate update = 2;/  ModelUpdate update = 2;/'
plant "nupmpc.v1.GetServerInfoResponse.errors_by_code: field 6 retyped from map<string, uint64> to map<string, uint32>" \
  's/^  map<string, uint64> errors_by_code = 6;/  map<string, uint32> errors_by_code = 6;/'
plant "nupmpc.v1.ControlRequest.sequence: field 3 moved from no oneof to oneof attach" \
  '/^  uint64 sequence = 3;/d; s/^    ProblemSpec spec = 2;/&\n    uint64 sequence = 3;/'
plant "nupmpc.v1.SessionInfo.idle_s: field 5 JSON name changed from idleS to idleSeconds" \
  's/^  double idle_s = 5;/  double idle_s = 5 [json_name = "idleSeconds"];/'
plant "nupmpc.v1.SolveStatus.SOLVE_STATUS_SUPERSEDED: enum value 6 removed" '/^  SOLVE_STATUS_SUPERSEDED = 6;/d'
plant "nupmpc.v1.WarmStart.WARM_START_COLD: enum value renumbered from 3 to 4" \
  's/^  WARM_START_COLD = 3;/  WARM_START_COLD = 4;/'
plant "nupmpc.v1.FleetAnswer: message removed" 's/\bFleetAnswer\b/StepAnswer/g'
plant "nupmpc.v1.MpcService.SolveOnce: RPC removed" '/^  rpc SolveOnce(/d'
plant "nupmpc.v1.MpcService.Control: RPC request changed from stream nupmpc.v1.ControlRequest to nupmpc.v1.ControlRequest" \
  's/^  rpc Control(stream ControlRequest)/  rpc Control(ControlRequest)/'
plant "nupmpc.v1.MpcService.Solve: RPC response changed from nupmpc.v1.SolveResponse to stream nupmpc.v1.SolveResponse" \
  's/^  rpc Solve(SolveRequest) returns (SolveResponse);/  rpc Solve(SolveRequest) returns (stream SolveResponse);/'
plant "nupmpc/v1/nupmpc.proto: package changed from 'nupmpc.v1' to 'nupmpc.v2'" 's/^package nupmpc.v1;/package nupmpc.v2;/'

# `update` refuses a breaking change and leaves the baseline as it was.
echo "-- update with a breaking change"
sed -i '/^  rpc SolveOnce(/d' "$api"
expect update 1 "nupmpc.v1.MpcService.SolveOnce: RPC removed"
expect update 1 "Not updating the baseline"
if ! cmp -s "$baseline" "$work/baseline.orig"; then
  echo "FAIL: update wrote a breaking change into the baseline" >&2
  exit 1
fi
cp "$work/api.orig" "$api"

# A field retired properly (number and name reserved) is compatible, and goes into the baseline.
echo "-- retired: Step.reference"
sed -i 's/^  repeated double reference = 7;/  reserved 7;\n  reserved "reference";/' "$api"
expect check 1 "nupmpc.v1.Step.reference: field 7 retired (number and name reserved)"
expect check 1 "Run \`tests/build/proto_compat_check.py update"
expect update 0 "wrote proto/api_baseline/nupmpc_v1.txtpb"
expect check 0 "compatible with the baseline"
cp "$work/api.orig" "$api"
cp "$work/baseline.orig" "$baseline"

# An added field: compatible, but `check` fails until `update` has put it into the baseline.
echo "-- added: Step.planted_extra"
sed -i 's/^  ModelUpdate model = 8;/&\n  double planted_extra = 99;/' "$api"
expect check 1 "nupmpc.v1.Step.planted_extra: field 99 added (double)"
expect check 1 "Run \`tests/build/proto_compat_check.py update"
expect update 0 "wrote proto/api_baseline/nupmpc_v1.txtpb"
grep -q '"planted_extra"' "$baseline" || { echo "FAIL: update did not write the addition" >&2; exit 1; }
expect check 0 "compatible with the baseline"
echo "ok: the check fails on every planted breaking change, and takes additions through update"
