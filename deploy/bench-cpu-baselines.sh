#!/usr/bin/env bash
# The core's speed per CPU baseline, measured in one run: builds nupmpc-bench for each
# baseline given (default: the portable default x86-64-v3 and native) in build-cpu-<baseline>/,
# then runs the instances round-robin, one baseline after the other, REPEAT rounds, and
# prints the median over rounds of each one's median cold solve (and, for instances with a
# closed loop, warm step) time, with the ratio to the first baseline.
#   deploy/bench-cpu-baselines.sh [BASELINE...]    (env: ROUNDS=3, NUPMPC_BENCHMARKS)
set -euo pipefail
cd "$(dirname "$0")/.."
benchmarks="${NUPMPC_BENCHMARKS:-benchmarks}"
rounds="${ROUNDS:-3}"
baselines=("$@")
[ ${#baselines[@]} -gt 0 ] || baselines=(x86-64-v3 native)
instances=(masses_N30 masses_N300 masses_N3000 masses_N30000 corridor_N175 ibffd_2d_N100
           random_outbox_M40_K20_L20_N1000_s1)
deploy/install-deps.sh
for b in "${baselines[@]}"; do
  echo "== building nupmpc-bench for $b (build-cpu-$b/)"
  cmake -S . -B "build-cpu-$b" -G Ninja -DCMAKE_BUILD_TYPE=Release -DNUPMPC_BUILD_TESTS=OFF \
    -DNUPMPC_CPU_BASELINE="$b" >/dev/null
  cmake --build "build-cpu-$b" -j "$(nproc)" --target nupmpc-bench >/dev/null
done
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for r in $(seq "$rounds"); do
  for i in "${instances[@]}"; do
    for b in "${baselines[@]}"; do
      "build-cpu-$b/bin/nupmpc-bench" --json "$benchmarks/$i.json" >>"$out/$b.jsonl"
    done
  done
done
python3 - "$out" "${baselines[@]}" <<'PY'
import json, statistics, sys
out, baselines = sys.argv[1], sys.argv[2:]
runs = {b: [json.loads(l) for l in open(f"{out}/{b}.jsonl")] for b in baselines}
def median(b, name, key):
    values = [key(r) for r in runs[b] if r["name"] == name and key(r) is not None]
    return statistics.median(values) if values else None
cold = lambda r: r["solve_ms"]
warm = lambda r: r.get("closed_loop", {}).get("warm_median_ms")
names = list(dict.fromkeys(r["name"] for r in runs[baselines[0]]))
head = "".join(f"{b + ' ms':>16}" + (f"{'ratio':>8}" if b != baselines[0] else "") for b in baselines)
print(f"{'instance':<40}{head}")
for name in names:
    for label, key in (("cold solve", cold), ("warm step", warm)):
        first = median(baselines[0], name, key)
        if first is None:
            continue
        row = f"{name + ' ' + label:<40}"
        for b in baselines:
            v = median(b, name, key)
            row += f"{v:>16.4f}" + (f"{v / first:>8.2f}" if b != baselines[0] else "")
        print(row)
PY
