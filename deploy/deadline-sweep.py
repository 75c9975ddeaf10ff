#!/usr/bin/python3
"""Deadlines met under mixed control periods, earliest deadline first against FIFO.

Two groups of Control streams (nupmpc-period-groups, the client library's period option):
many short-period streams of a small problem and a few long-period streams of a larger one,
each group offering half of the load. The server runs on one CPU with one worker, the
streams on another.

The load levels are shares of the core's capacity for this mix, paced: the rate of steps
at which the server's core would be busy all the time. It is calibrated in two steps.
First each instance's streams step as fast as answers come, alone: that sets the two
groups' shares (half of the work each). Paced steps cost the server more than that (each
arrives alone, so every one pays its own wake-ups and writes), so the mix is then run paced
at two levels of that first estimate, and the server's CPU share, a straight line in the
offered rate, is extrapolated to one full CPU. Both estimates are printed, and every run
prints the server's CPU share, so a reader can see what each level really loaded.

Then, for each load level, an EDF and a FIFO server are run in turn (their order
alternating from level to level), and the script prints per level, scheduling and group:
steps, met, missed by cause, the slack's median and worst percent, and how evenly the
group's streams were served.

    deploy/deadline-sweep.py [--levels 0.5,0.9,1.0,1.2] [--seconds 5] [--repeat N] [--json FILE]
                             [--capacity short=R,long=R]

With --repeat N the whole sweep, calibration included, runs N times and a summary gives
each figure's median and range: a shared machine's speed drifts within minutes, and a
level near the capacity is then a little under or over it. --capacity short=R,long=R skips
the calibration and offers the levels of that capacity (as a calibration prints it), to
compare two builds at the same offered load.

Run by deploy/loadtest.sh; --quick (short runs, two levels) is the ctest smoke
LoadTest.DeadlineSweepCountsEveryStep, which checks mechanisms, never speed."""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import time
import urllib.request

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "client" / "python"))
sys.path.insert(0, os.environ.get("NUPMPC_PYTHON_STUBS", str(REPO / "build" / "python")))
from nupmpc.local_server import LocalServer, free_loopback_ports  # noqa: E402

BIN = pathlib.Path(os.environ.get("NUPMPC_BIN_DIR", str(REPO / "build" / "bin")))
BENCHMARKS = pathlib.Path(os.environ.get("NUPMPC_BENCHMARK_DIR", str(REPO / "benchmarks")))
GROUPS = [("short", "masses_N30.json", 32), ("long", "masses_N300.json", 8)]
SCHEDULINGS = ("edf", "fifo")
# Shares of the unpaced estimate the paced calibration runs at: far enough apart for a
# slope, and below saturation (where the CPU share stops growing with the load).
PACED_CALIBRATION_LEVELS = (0.3, 0.6)


def cpus():
    """(server's CPUs, the streams' CPUs): one each on a machine with two or more."""
    count = os.cpu_count() or 1
    return ([0], [1]) if count >= 2 else (None, None)


def server(scheduling, server_cpus):
    """A server on `server_cpus` with one worker, and its metrics endpoint's address."""
    metrics = f"127.0.0.1:{free_loopback_ports(1)[0]}"
    s = LocalServer(BIN / "nupmpc-server", "--threads", "1", "--scheduling", scheduling, "--metrics_address", metrics,
                    cpus=server_cpus, env={**os.environ, "NUPMPC_LOG_LEVEL": "warn"})
    s.metrics_address = metrics
    return s


def server_deadlines(s):
    """The server's own count of steps by deadline outcome (nupmpc_step_deadlines_total),
    warm-up included: met by the server's clock, from its receipt to its send."""
    with urllib.request.urlopen(f"http://{s.metrics_address}/metrics", timeout=10) as reply:
        text = reply.read().decode()
    counts = {}
    for line in text.splitlines():
        if line.startswith("nupmpc_step_deadlines_total{"):
            outcome = line.split('outcome="', 1)[1].split('"', 1)[0]
            counts[outcome] = int(float(line.rsplit(" ", 1)[1]))
    return counts


def period_groups(target, group_flag, client_cpus, *flags):
    command = [str(BIN / "nupmpc-period-groups"), "--server", target, "--group", group_flag, *flags]
    if client_cpus is not None:
        command = ["taskset", "-c", ",".join(map(str, client_cpus)), *command]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        sys.exit(f"deadline-sweep: {' '.join(command)} failed: {done.stderr.strip()}")
    return json.loads(done.stdout)


def unpaced_capacity(server_cpus, client_cpus, seconds):
    """Steps per second the server gives each group's streams stepping as fast as answers
    come, each group alone: its capacity for that instance at that concurrency."""
    with_one = ",".join(f"{name}:{BENCHMARKS / file}:{streams}:1000" for name, file, streams in GROUPS)
    s = server("edf", server_cpus).start()
    try:
        return period_groups(s.target, with_one, client_cpus, "--calibrate_s", str(seconds))["steps_per_s"]
    finally:
        s.stop()


def groups_at(level, capacity):
    """The --group flag offering `level` of the capacity, half from each group."""
    parts, periods = [], {}
    for name, file, streams in GROUPS:
        period_ms = streams / capacity[name] / (level / len(GROUPS)) * 1e3
        periods[name] = period_ms
        parts.append(f"{name}:{BENCHMARKS / file}:{streams}:{period_ms:.3f}")
    return ",".join(parts), periods


def paced_cpu_share(level, capacity, server_cpus, client_cpus, seconds):
    """The server's CPU share under the paced mix offered at `level` of `capacity`."""
    flag, _ = groups_at(level, capacity)
    s = server("edf", server_cpus).start()
    try:
        cpu_before, started = cpu_seconds(s.process.pid), time.monotonic()
        period_groups(s.target, flag, client_cpus, "--seconds", str(seconds), "--warmup_s", "0.5")
        return (cpu_seconds(s.process.pid) - cpu_before) / (time.monotonic() - started)
    finally:
        s.stop()


def paced_capacity(unpaced, server_cpus, client_cpus, seconds):
    """The capacity for the paced mix: the unpaced estimate scaled to where the server's
    CPU share, measured at two paced levels below saturation, reaches one CPU."""
    low, high = PACED_CALIBRATION_LEVELS
    share_low = paced_cpu_share(low, unpaced, server_cpus, client_cpus, seconds)
    share_high = paced_cpu_share(high, unpaced, server_cpus, client_cpus, seconds)
    slope = (share_high - share_low) / (high - low)
    full = high + (1.0 - share_high) / slope if slope > 0.0 else 0.0
    if not high <= full <= 2.0:
        # A machine busy with other work gives the server less than its CPU: the shares say
        # nothing about its capacity then. The unpaced estimate stands, and the runs' own
        # CPU shares show what the levels really loaded.
        print(f"deadline-sweep: paced calibration unusable (server CPU {share_low:.0%} at {low:.0%}, "
              f"{share_high:.0%} at {high:.0%}): is the machine busy? The levels are shares of the unpaced "
              f"estimate", flush=True)
        return dict(unpaced), {"low": [low, share_low], "high": [high, share_high], "usable": False}
    print(f"paced calibration: server CPU {share_low:.0%} at {low:.0%} and {share_high:.0%} at {high:.0%} "
          f"of the unpaced estimate: one full CPU at {full:.0%} of it", flush=True)
    return {name: rate * full for name, rate in unpaced.items()}, {"low": [low, share_low], "high": [high, share_high]}


def sweep(levels, seconds, server_cpus, client_cpus, calibrate_s, paced=True, given_capacity=None):
    unpaced, paced_shares = None, None
    if given_capacity is not None:
        capacity = dict(given_capacity)
        print("capacity given (--capacity): " + ", ".join(f"{k} {v:.0f}" for k, v in capacity.items()), flush=True)
    else:
        unpaced = unpaced_capacity(server_cpus, client_cpus, calibrate_s)
        print(f"unpaced capacity (steps/s of each group's streams alone, as fast as answers come): "
              + ", ".join(f"{k} {v:.0f}" for k, v in unpaced.items()), flush=True)
        if paced:
            capacity, paced_shares = paced_capacity(unpaced, server_cpus, client_cpus, 2 * calibrate_s)
            print(f"capacity for the paced mix (steps/s of each group at one full CPU): "
                  + ", ".join(f"{k} {v:.0f}" for k, v in capacity.items()), flush=True)
        else:
            capacity = dict(unpaced)
            print("levels are shares of the unpaced estimate (no paced calibration)", flush=True)
    runs = []
    for i, level in enumerate(levels):
        flag, periods = groups_at(level, capacity)
        order = SCHEDULINGS if i % 2 == 0 else tuple(reversed(SCHEDULINGS))
        for scheduling in order:
            s = server(scheduling, server_cpus).start()
            try:
                cpu_before, started = cpu_seconds(s.process.pid), time.monotonic()
                figures = period_groups(s.target, flag, client_cpus, "--seconds", str(seconds), "--warmup_s", "1")
                server_cpu_share = (cpu_seconds(s.process.pid) - cpu_before) / (time.monotonic() - started)
                deadlines = server_deadlines(s)
            finally:
                s.stop()
            runs.append({"level": level, "scheduling": scheduling, "periods_ms": periods,
                         "server_cpu_share": round(server_cpu_share, 3), "server_deadlines": deadlines, **figures})
            print_run(runs[-1])
    return {"unpaced_capacity_steps_per_s": unpaced, "paced_calibration_cpu_shares": paced_shares,
            "capacity_steps_per_s": capacity, "runs": runs}


def cpu_seconds(pid):
    """User and system CPU time of a process so far (/proc/PID/stat, fields 14 and 15)."""
    fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def print_run(run):
    # A side near 100 % of its one CPU set the pace: the server's (misses are the
    # scheduler's) or the streams' (held steps are partly the load generator's own).
    # The server's count is by its own clock (receipt to send): steps it met that the
    # streams held lost their time between the two processes.
    d = run["server_deadlines"]
    print(f"load {run['level']:4.0%} {run['scheduling']:4} CPU: server {run['server_cpu_share']:.0%}, "
          f"streams {run['client_cpu_share']:.0%}; the server's own count: met {d.get('met', 0)} of "
          f"{sum(d.values())} steps with a deadline", flush=True)
    for g in run["groups"]:
        m = g["missed_by_cause"]
        print(f"load {run['level']:4.0%} {run['scheduling']:4} {g['group']:5} {g['streams']:3} x {g['period_ms']:7.2f} ms: "
              f"{g['steps']:6} steps, missed {g['missed_share']:7.3%} (queued {m['queued_past_deadline']}, "
              f"too long {m['solve_too_long']}, held {m['held']}, other {m['other']}, errors {m['errors']}), "
              f"slack p50 {g['slack_p50_ms']:7.3f} ms, p1 {g['slack_p01_ms']:8.3f} ms, "
              f"streams met {g['stream_min_share']:.2f}..{g['stream_max_share']:.2f} x mean", flush=True)


def summarize(sweeps):
    """Per level, scheduling and group: the missed share's median and range over the sweeps."""
    cells = {}
    for result in sweeps:
        for run in result["runs"]:
            for g in run["groups"]:
                key = (run["level"], run["scheduling"], g["group"])
                cells.setdefault(key, []).append(g["missed_share"])
    print(f"missed share over {len(sweeps)} sweeps, median (min..max):", flush=True)
    for (level, scheduling, group), shares in sorted(cells.items()):
        shares.sort()
        print(f"load {level:4.0%} {scheduling:4} {group:5}: {statistics.median(shares):7.3%} "
              f"({shares[0]:.3%}..{shares[-1]:.3%})", flush=True)


def check(result):
    """The mechanisms every run must show, whatever the machine's speed: each step counted
    once, by outcome, and no stream of a group left without deadlines met at low load."""
    problems = []
    for run in result["runs"]:
        for g in run["groups"]:
            m = g["missed_by_cause"]
            counted = g["met"] + sum(m.values())
            if g["steps"] == 0 or counted != g["steps"]:
                problems.append(f"{run['scheduling']} at {run['level']}: {g['group']} counted {counted} of {g['steps']}")
            if m["errors"]:
                problems.append(f"{run['scheduling']} at {run['level']}: {g['group']} had {m['errors']} errors")
            if run["level"] <= 0.5 and g["stream_min_share"] <= 0.0:
                problems.append(f"{run['scheduling']} at {run['level']}: a {g['group']} stream met no deadline")
    return problems


def parse_capacity(text, parser):
    """--capacity short=R,long=R: a positive rate (steps/s) for each group."""
    given = {}
    for part in text.split(","):
        name, _, rate = part.partition("=")
        try:
            given[name.strip()] = float(rate)
        except ValueError:
            parser.error(f"--capacity {text}: '{part}' is not GROUP=RATE")
    if sorted(given) != sorted(name for name, _, _ in GROUPS) or min(given.values()) <= 0.0:
        parser.error(f"--capacity {text}: give a positive rate for each of the groups "
                     + ", ".join(name for name, _, _ in GROUPS))
    return given


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", default="0.5,0.9,1.0,1.2", help="load levels, shares of the capacity")
    parser.add_argument("--seconds", type=float, default=5.0, help="counted time per run")
    parser.add_argument("--repeat", type=int, default=1, help="run the whole sweep this many times")
    parser.add_argument("--json", help="write every figure to this file")
    parser.add_argument("--capacity", help="skip the calibration and use this capacity, e.g. short=4600,long=480 "
                        "(steps/s of each group at one full CPU, as a calibration prints it): two builds "
                        "or machines compared at the same offered load")
    parser.add_argument("--quick", action="store_true",
                        help="short runs at 0.3 and 1.2 of the unpaced estimate (the ctest smoke)")
    args = parser.parse_args()
    levels = [0.3, 1.2] if args.quick else [float(v) for v in args.levels.split(",")]
    seconds = 1.5 if args.quick else args.seconds
    server_cpus, client_cpus = cpus()
    # The smoke checks mechanisms, not levels: it skips the paced calibration, which a
    # machine busy with other tests would make meaningless anyway.
    given = parse_capacity(args.capacity, parser) if args.capacity else None
    sweeps = [sweep(levels, seconds, server_cpus, client_cpus, 0.5 if args.quick else 2.0, paced=not args.quick,
                    given_capacity=given)
              for _ in range(max(args.repeat, 1))]
    if len(sweeps) > 1:
        summarize(sweeps)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(sweeps[0] if len(sweeps) == 1 else {"sweeps": sweeps}, indent=1))
    problems = [p for result in sweeps for p in check(result)]
    for p in problems:
        print(f"deadline-sweep: {p}", file=sys.stderr)
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
