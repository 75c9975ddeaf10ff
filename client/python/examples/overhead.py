"""The Python session's round trip next to the C++ client's, in the same run: a Control
stream at concurrency 1 through the masses_N30 closed-loop states (the load test's
workload), first from Python (nupmpc.Session.step, then nupmpc.aio), then from nupmpc-loadtest
(--concurrency 1 --echo=false, the C++ client library), against the same server.
Prints p50/p90 round trip and the server's p50 solve time of each."""

import asyncio
import json
import os
import subprocess
import time

import numpy as np

from _common import BENCHMARKS, REPO, arguments

import nupmpc

args = arguments(__doc__, duration_s=(5.0, "seconds per client"),
                 loadtest_binary=(os.environ.get("NUPMPC_LOADTEST_BINARY",
                                                 str(REPO / "build" / "bin" / "nupmpc-loadtest")), "nupmpc-loadtest"))
instance_path = BENCHMARKS / "masses_N30.json"
instance = nupmpc.load_instance(instance_path)
states = instance.closed_loop_states



def blocking():
    with nupmpc.connect(args.server) as client:
        session = client.session(instance.problem)
        for x in states[:20]:  # warm-up, as the load test's --warmup_s
            session.step(x)
        plans, end = [], time.monotonic() + args.duration_s
        while time.monotonic() < end:
            plans.append(session.step(states[len(plans) % len(states)]))
        session.close()
    return plans


async def asynchronous():
    async with nupmpc.aio.connect(args.server) as client:
        session = await client.session(instance.problem)
        for x in states[:20]:
            await session.step(x)
        plans, end = [], time.monotonic() + args.duration_s
        while time.monotonic() < end:
            plans.append(await session.step(states[len(plans) % len(states)]))
        await session.close()
    return plans


python = {"Python (nupmpc.Session)": blocking(), "Python (nupmpc.aio)": asyncio.run(asynchronous())}

out = subprocess.run([args.loadtest_binary, "--server", args.server, "--instance", str(instance_path),
                      "--concurrency", "1", "--echo=false", "--duration_s", str(args.duration_s), "--json",
                      "--progress", "off"], capture_output=True, text=True)
if out.returncode != 0:
    raise SystemExit(f"nupmpc-loadtest failed: {out.stderr.strip()}")
level = json.loads(out.stdout)["levels"][0]

print(f"masses_N30, concurrency 1, {args.duration_s:g} s each, server {args.server}")
print(f"{'client':<28}{'steps':>8}{'p50 round trip':>16}{'p90':>10}{'server solve p50':>18}")
for name, plans in python.items():
    round_trips = [p.round_trip_ms for p in plans]
    print(f"{name:<28}{len(plans):>8}{np.percentile(round_trips, 50):>13.3f} ms"
          f"{np.percentile(round_trips, 90):>7.3f} ms{np.median([p.solve_ms for p in plans]):>15.3f} ms")
print(f"{'C++ (nupmpc-loadtest)':<28}{level['solves']:>8}{level['p50_ms']:>13.3f} ms{level['p90_ms']:>7.3f} ms"
      f"{level['server_solve_p50_ms']:>15.3f} ms")
for name, plans in python.items():
    p50 = np.percentile([p.round_trip_ms for p in plans], 50)
    print(f"{name} over C++ at p50: {p50 - level['p50_ms']:+.3f} ms")
