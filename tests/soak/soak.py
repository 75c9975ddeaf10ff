#!/usr/bin/python3
"""Soak: the real nupmpc-server under saturating mixed load for a while, its memory
sampled throughout, to catch leaks and slow growth that short tests miss.

    tests/soak/soak.py [--seconds 600] [--period_s 60] [--streams 16] [--warmup_s 120]

The load, all at once:
  * bulk: nupmpc-loadtest (C++, closed loop, --new_references) with --streams Control
    streams on masses_N30, a new state and new output references every step; one run per
    period, so its sessions are created and closed every period;
  * churn: sessions created over a Control stream, stepped three times, closed, without pause;
  * a few keep-out sessions (a point mass driven around two regions from the start) and
    GP-MPC sessions (a new reference every step) at a control period of 50 ms, each closed
    and re-created every 20 steps (the GP factorisation is shared while one is held).
The server's resident memory (VmRSS from /proc) is sampled every --sample_s seconds. One
table row per period: bulk steps, solves/s, p50/p99/max round trip, other steps, errors
by code, RSS. Exit 1 when any error other than RESOURCE_EXHAUSTED (the documented
overload refusal) occurred, when a period's peak RSS after the warm-up exceeds the first
such period's by more than --max_drift, or when a part of the load did no work. Peaks,
not means: within a period RSS dips each time a bulk run's sessions are freed, and its
high-water mark is what a leak raises and what the memory limit has to hold."""

import argparse
import asyncio
import json
import os
import subprocess
import sys
import threading
import time
from collections import Counter

import numpy as np

import harness
from harness import nupmpc

LOADTEST_BINARY = os.environ.get("NUPMPC_LOADTEST_BINARY", str(harness.REPO / "build" / "bin" / "nupmpc-loadtest"))
ALLOWED_ERRORS = {"RESOURCE_EXHAUSTED"}
PERIOD_S = 0.05  # control period of the keep-out and GP sessions


class Side:
    """The Python side of the load (churn, keep-out and GP sessions) on an asyncio loop of
    its own thread; counts by period."""

    def __init__(self, target, spec, states, special_sessions):
        self.target, self.spec, self.states = target, spec, states
        self.special_sessions = special_sessions
        self.lock = threading.Lock()
        self.counts = Counter()  # churn_sessions, churn_steps, keep_out_steps, gp_steps, error:CODE
        self.stopping = False
        self.thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)

    def take(self):
        with self.lock:
            counts, self.counts = self.counts, Counter()
        return counts

    def _count(self, key, n=1):
        with self.lock:
            self.counts[key] += n

    async def _guarded(self, body):
        """Runs body() until stopped; an error is counted by code and the loop goes on."""
        while not self.stopping:
            try:
                await body()
            except nupmpc.NupmpcError as error:
                self._count(f"error:{error.code.name}")
                await asyncio.sleep(0.05)

    async def _churn(self, client, index):
        step = index

        async def body():
            nonlocal step
            session = await client.session(self.spec)
            self._count("churn_sessions")
            try:
                for _ in range(3):
                    await session.step(self.states[step % len(self.states)])
                    step += 1
                    self._count("churn_steps")
            finally:
                await session.close()
        await self._guarded(body)

    async def _special(self, client, problem, key, x0, plant, step_arguments):
        """Sessions of `problem` stepped every PERIOD_S on `plant` (x, u → next x) from x0,
        with step_arguments(t) besides the state, 20 steps each."""
        async def body():
            session = await client.session(problem)
            x = np.asarray(x0, dtype=float)
            try:
                for t in range(20):
                    if self.stopping:
                        break
                    next_period = asyncio.sleep(PERIOD_S)
                    plan = await session.step(x, **step_arguments(t))
                    self._count(key)
                    if plan.has_plan:
                        x = plant(x, plan.u0)
                    await next_period
            finally:
                await session.close()
        await self._guarded(body)

    async def _main(self):
        async with nupmpc.aio.connect(self.target) as client:
            tasks = [self._churn(client, i) for i in range(2)]
            for i in range(self.special_sessions):
                keep_out, point_mass = harness.keep_out_problem()
                tasks.append(self._special(client, keep_out, "keep_out_steps", [0, 0, 0, 0], point_mass,
                                           lambda t: {}))
                # The GP session's state is the window [y[t-1], u[t-1]]; a plant that follows
                # the GP's own reference closely enough for a soak.
                tasks.append(self._special(client, harness.gp_problem(seed=i), "gp_steps", [0.0, 0.0],
                                           lambda x, u: np.array([0.9 * x[0] + 0.4 * np.tanh(u[0]), u[0]]),
                                           lambda t: {"references": [0.5 + 0.02 * (t % 10)]}))
            await asyncio.gather(*tasks)

    def start(self):
        self.thread.start()

    def stop(self):
        self.stopping = True
        self.thread.join(timeout=60)


class RssSampler(threading.Thread):
    def __init__(self, server, every_s):
        super().__init__(daemon=True)
        self.server, self.every_s = server, every_s
        self.samples = []  # (seconds since start, bytes)
        self.start_time = time.monotonic()
        self.stopped = threading.Event()

    def run(self):
        while not self.stopped.is_set():
            self.samples.append((time.monotonic() - self.start_time, self.server.rss_bytes()))
            self.stopped.wait(self.every_s)


def run_bulk(target, streams, duration_s):
    """One period of nupmpc-loadtest; its JSON level report."""
    command = [LOADTEST_BINARY, "--server", target, "--instance", str(harness.MASSES),
               "--concurrency", str(streams), "--duration_s", str(duration_s),
               "--warmup_s", "0", "--new_references", "--echo=false", "--baseline_rounds", "1",
               "--transport_calls", "10", "--progress", "off", "--json"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=duration_s + 120)
    if done.returncode != 0:
        raise harness.HarnessError(f"nupmpc-loadtest exited with {done.returncode}: {done.stderr[-2000:]}")
    return json.loads(done.stdout)["levels"][0]


def mib(n):
    return n / 2**20


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=600.0, help="total soak time")
    parser.add_argument("--period_s", type=float, default=60.0, help="one table row (and one bulk run) per period")
    parser.add_argument("--warmup_s", type=float, default=120.0, help="RSS before this is not compared")
    parser.add_argument("--sample_s", type=float, default=10.0, help="RSS sampling interval")
    parser.add_argument("--streams", type=int, default=16, help="bulk Control streams (nupmpc-loadtest)")
    parser.add_argument("--special_sessions", type=int, default=2, help="keep-out and GP sessions, each")
    parser.add_argument("--max_drift", type=float, default=0.05, help="allowed RSS growth after the warm-up")
    args = parser.parse_args()
    periods = max(1, round(args.seconds / args.period_s))
    if periods * args.period_s - args.warmup_s < 2 * args.period_s:
        parser.error(f"--seconds {args.seconds:g}: must leave two periods of --period_s {args.period_s:g} after "
                     f"--warmup_s {args.warmup_s:g} (the first is the one the others are compared with)")

    spec, states = harness.masses()
    server = harness.Server("--threads", "2")
    failures = []
    try:
        sampler = RssSampler(server, args.sample_s)
        sampler.start()
        side = Side(server.target, spec, states, args.special_sessions)
        side.start()
        rows, all_errors = [], Counter()
        print(f"soak: {periods} × {args.period_s:g} s against {server.target} (pid {server.pid}), "
              f"{args.streams} bulk streams, RSS every {args.sample_s:g} s", flush=True)
        print(f"{'period':>6} {'end s':>6} {'bulk steps':>10} {'solves/s':>8} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7} "
              f"{'churn sess':>10} {'keep-out':>8} {'gp':>5} {'no plan':>7} {'RSS MiB':>8}  errors", flush=True)
        for period in range(periods):
            level = run_bulk(server.target, args.streams, args.period_s - 1.0)
            side_counts = side.take()
            errors = Counter(level["errors"])
            errors.update({k.split(":", 1)[1]: v for k, v in side_counts.items() if k.startswith("error:")})
            all_errors.update(errors)
            end_s = time.monotonic() - sampler.start_time
            rss = server.rss_bytes()
            rows.append((period, end_s, rss))
            print(f"{period + 1:>6} {end_s:>6.0f} {level['solves']:>10} {level['solves_per_s']:>8.0f} "
                  f"{level['p50_ms']:>7.2f} {level['p99_ms']:>7.2f} {level['max_ms']:>7.1f} "
                  f"{side_counts['churn_sessions']:>10} {side_counts['keep_out_steps']:>8} {side_counts['gp_steps']:>5} "
                  f"{level['no_plan']:>7} {mib(rss):>8.1f}  {dict(errors) or '-'}", flush=True)
            for what, n in (("bulk steps", level["solves"]), ("churned sessions", side_counts["churn_sessions"]),
                            ("keep-out steps", side_counts["keep_out_steps"]), ("GP steps", side_counts["gp_steps"])):
                if n == 0:
                    failures.append(f"period {period + 1}: no {what}")
        side.stop()
        sampler.stopped.set()
        sampler.join()
        info_errors = {code: n for code, n in all_errors.items() if code not in ALLOWED_ERRORS}
        if info_errors:
            failures.append(f"errors other than RESOURCE_EXHAUSTED: {info_errors}")
        # Peak RSS per period after the warm-up, against the first such period.
        by_period = {}
        for t, rss in sampler.samples:
            if t >= args.warmup_s:
                by_period.setdefault(int(t // args.period_s), []).append(rss)
        peaks = [max(v) for _, v in sorted(by_period.items())]
        samples_line = " ".join(f"{mib(rss):.1f}" for _, rss in sampler.samples)
        print(f"RSS samples (MiB, every {args.sample_s:g} s): {samples_line}")
        if len(peaks) >= 2:
            drift = max(peaks[1:]) / peaks[0] - 1.0
            print(f"RSS after warm-up: first period peak {mib(peaks[0]):.1f} MiB, highest later peak "
                  f"{mib(max(peaks[1:])):.1f} MiB: drift {100 * drift:+.2f} % (limit {100 * args.max_drift:g} %)")
            if drift > args.max_drift:
                failures.append(f"RSS drift {100 * drift:.2f} % > {100 * args.max_drift:g} %")
        else:
            failures.append("too few RSS samples after the warm-up to compare")
        print(f"errors by code over the run: {dict(all_errors) or 'none'}")
    finally:
        server.stop()
    for f in failures:
        print(f"FAIL: {f}")
    print("soak: " + ("FAIL" if failures else "PASS"))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
