#!/usr/bin/python3
"""Quiet network faults against the real nupmpc-server binary: faults that send no error
(a partition, a frozen server, lost packets), which only a client that keeps time can
see. Each scenario runs in a private network namespace of its own (the script re-executes
itself under `unshare --net`), where the faults are nftables rules on its loopback, so
they touch nothing else on the machine; each prints a PASS/FAIL line and its figures:

  cli_partition_2s, cli_partition_10s, cli_partition_60s
               `nupmpc closed-loop --period_ms 50`; every TCP packet to or from the server's
               port dropped for 2, 10 or 60 s after 3 s of steps, then healed: a step line
               every period throughout (the partition's held steps counted within bounds),
               plans again within 2 s of the heal, the summary's held_steps and reconnects
               (at least one from 10 s on: the client found the dead stream), and sampled
               plans equal to a cold solve of their own step's state
  python_partition_2s, python_partition_10s, python_partition_60s
               the same with the Python client (session(spec, period=0.05), step() paced
               at the period; every step() returns within the period + 0.5 s)
  frozen_server  the server stopped (SIGSTOP) for 10 s under the CLI: held steps in the
               same bounds, plans again within 2 s of SIGCONT
  loss_5, loss_30  5 % and 30 % of the server port's packets dropped at random for 10 s
               under the CLI: a step line every period, plans within 2 s after the loss,
               the plans applied during the loss for their own step's state
  haproxy_replica_partition  three replicas behind HAProxy, 24 Control streams of the
               Python client; one replica's port partitioned (HAProxy keeps the clients'
               connections up, so only the clients' rule of K held periods can find it): its
               streams get plans again within 5 s, the others miss at most 2 periods

    tests/soak/quiet_faults.py [--quick] [--jobs N] [SCENARIO ...]

The scenarios given (default: all) run at once, each in its own namespace (--jobs bounds
how many at a time), so a group takes about as long as its longest scenario. Needs root
(unshare, nft), nftables, iproute2 and haproxy (deploy/install-deps.sh). Exit 1 when any
scenario fails. --quick: shorter phases around the faults (the ctest QuietFaults.*);
the faults themselves last what the names say either way.

Every bound is on a mechanism (held steps counted, a step line every period, plans again
after the fault, plans for their own state) with generous slack, never on machine speed."""

import argparse
import importlib.util
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass

import numpy as np

import harness
from faults import CLI_BINARY, Result, wait_for
from harness import nupmpc
from nupmpc.local_server import free_loopback_ports

HOST = "127.0.0.1"
PERIOD_S = 0.05
PERIOD_MS = round(PERIOD_S * 1000)
# A step may take the period plus this (a step line's gap, a step() call): the room a
# loaded machine needs, far below any outage a client could be hiding.
STEP_SLACK_S = 0.5
# Held steps during an outage of D seconds: at least this share of D / period (the first
# step of the outage may still be answered, pacing may slip a little) and at most
# (D + HELD_EXTRA_S) / period (more would be held steps counted twice, or not paced).
HELD_LEAST_SHARE = 0.9
HELD_EXTRA_S = 2.0
PLANS_AGAIN_WITHIN_S = 2.0  # after a heal (or SIGCONT, or the loss's end)
SPOT_CHECKS = 5
SPOT_TOLERANCE = 1e-4  # a warm-started plan against a cold solve of the same state
# Behind HAProxy: K held periods, a 1 s attempt, 0.5 s of back-off, and slack.
REPLICA_RECOVERY_S = 5.0
# Periods in a row without a plan on a replica that is fine: the step slack's worth (a
# loaded machine stalls a client loop for a few periods), still far below the partitioned
# replica's outage, which a healthy stream caught behind it would share.
OTHER_STREAMS_MAY_MISS = round(STEP_SLACK_S / PERIOD_S)
STREAMS_BEHIND_HAPROXY = 24
REPLICAS = 3
CHILD_TIMEOUT_S = 300  # one scenario in its namespace, set-up and checks included

UNSHARE = shutil.which("unshare") or "/usr/bin/unshare"
NFT = shutil.which("nft") or "/usr/sbin/nft"
IP = shutil.which("ip") or "/usr/sbin/ip"
HAPROXY = shutil.which("haproxy") or "/usr/sbin/haproxy"
HAPROXY_CONFIG = harness.REPO / "deploy" / "haproxy" / "haproxy-config.sh"
HAPROXY_STAT = harness.REPO / "deploy" / "haproxy" / "haproxy-stat.py"


def phases(quick):
    """(seconds of steps before the fault, seconds after it)."""
    return (3.0, 5.0) if quick else (10.0, 15.0)


# The namespace.

_entered_namespace = False


def own_network_namespace():
    return os.readlink("/proc/self/ns/net")


def namespaced_command(script, host_namespace, *args):
    """The command that runs `script` (a Python file) with `args` in a new network
    namespace, told which namespace it was started from (see enter_namespace)."""
    return [UNSHARE, "--net", sys.executable, str(script), "--in_namespace", host_namespace, *args]


def enter_namespace(host_namespace):
    """In a re-executed child: refuses to go on in the namespace it was started from (the
    faults would cut the machine's own traffic), then brings the loopback up (a new
    namespace's is down)."""
    global _entered_namespace
    if own_network_namespace() == host_namespace:
        raise harness.HarnessError(f"still in the starting network namespace ({host_namespace}): not isolated")
    run_tool([IP, "link", "set", "lo", "up"])
    _entered_namespace = True


def run_tool(command, stdin=None):
    done = subprocess.run(command, input=stdin, capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise harness.HarnessError(f"{' '.join(map(str, command))} exited with {done.returncode}: {done.stderr.strip()}")
    return done.stdout


def sleep_until(at):
    delay = at - time.monotonic()
    if delay > 0:
        time.sleep(delay)


def reachable(port, timeout_s=0.5):
    """Whether a TCP connection to HOST:port opens within timeout_s."""
    try:
        socket.create_connection((HOST, port), timeout=timeout_s).close()
        return True
    except OSError:
        return False


# The faults: apply(), heal(), and report(result) for what they saw of themselves.

class Firewall:
    """One nftables table of this namespace: every TCP packet to or from a port dropped,
    all of them (a partition) or a random share (loss). On loopback every packet passes
    the output hook once, leaving its sender, so one output chain drops both directions;
    the counters show that the rules did drop packets. Deleting the table heals."""

    TABLE = "quiet_faults"

    def __init__(self):
        if not _entered_namespace:
            raise harness.HarnessError("nftables rules outside a private network namespace: refused")

    def drop(self, port, percent=100):
        share = "" if percent >= 100 else f"numgen random mod 100 < {percent} "
        run_tool([NFT, "-f", "-"], stdin=f"""
table inet {self.TABLE} {{
  chain output {{
    type filter hook output priority 0; policy accept;
    tcp sport {port} {share}counter drop
    tcp dport {port} {share}counter drop
  }}
}}
""")

    def dropped_packets(self):
        listing = json.loads(run_tool([NFT, "-j", "list", "table", "inet", self.TABLE]))
        return sum(expr["counter"]["packets"] for item in listing["nftables"] if "rule" in item
                   for expr in item["rule"]["expr"] if "counter" in expr)

    def heal(self):
        run_tool([NFT, "delete", "table", "inet", self.TABLE])


class Partition:
    """Every packet of `port` dropped; checked to refuse a new connection meanwhile and to
    take one again after the heal."""

    def __init__(self, port):
        self.port, self.firewall = port, Firewall()
        self.cut = self.restored = None
        self.dropped = 0

    def apply(self):
        self.firewall.drop(self.port)
        self.cut = not reachable(self.port)

    def heal(self):
        self.dropped = self.firewall.dropped_packets()
        self.firewall.heal()
        self.restored = reachable(self.port)

    def report(self, r):
        r.figures["packets_dropped"] = self.dropped
        r.check(self.cut, f"a connection to port {self.port} opened during the partition: the rules did not hold")
        r.check(self.restored, f"no connection to port {self.port} after the heal")
        r.check(self.dropped > 0, "the partition dropped no packet")


class Loss:
    """`percent` % of the packets of `port` dropped at random."""

    def __init__(self, port, percent):
        self.port, self.percent, self.firewall = port, percent, Firewall()
        self.dropped = 0

    def apply(self):
        self.firewall.drop(self.port, self.percent)

    def heal(self):
        self.dropped = self.firewall.dropped_packets()
        self.firewall.heal()

    def report(self, r):
        r.figures["packets_dropped"] = self.dropped
        r.check(self.dropped > 0, "the loss rule dropped no packet")


class Freeze:
    """The server process stopped (SIGSTOP) and continued (SIGCONT): its kernel still
    accepts connections and acknowledges data, nobody answers."""

    def __init__(self, server):
        self.server, self.stopped_state = server, None

    def apply(self):
        os.kill(self.server.pid, signal.SIGSTOP)
        # /proc's state T: the signal took effect (not merely sent).
        self.stopped_state = wait_for(lambda: self.process_state() == "T", 5)

    def heal(self):
        os.kill(self.server.pid, signal.SIGCONT)

    def process_state(self):
        with open(f"/proc/{self.server.pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0]

    def report(self, r):
        r.check(self.stopped_state, "the server never showed as stopped")


@dataclass
class Window:
    start: float
    end: float

    @property
    def length(self):
        return self.end - self.start


def inject(fault, start_at, duration_s):
    """Applies `fault` at start_at (monotonic), heals it duration_s later: its Window."""
    sleep_until(start_at)
    start = time.monotonic()
    try:
        fault.apply()
        sleep_until(start + duration_s)
    finally:
        end = time.monotonic()
        fault.heal()
    return Window(start, end)


# What a client did, step by step.

@dataclass(eq=False)  # records are compared by identity
class StepRecord:
    at: float               # time.monotonic() when the step returned (the CLI: when its line arrived)
    held: object            # the client gave the period up without an answer (None: not reported)
    has_plan: bool
    status: str
    state: object = None    # the state sent (np.ndarray; None: not reported)
    u0: object = None       # the input applied
    u: object = None        # the whole plan's inputs (Python), for the spot check
    clock_s: object = None  # the client's own time of the step (the CLI's t_s)
    call_s: object = None   # how long step() took (Python)
    index: int = 0          # the step's number in its run

    @property
    def converged(self):
        return self.status.upper() == "CONVERGED"  # the CLI prints it in lower case

    @property
    def fresh(self):
        """A plan computed for this step, applied."""
        return self.has_plan and not self.held


def as_array(values):
    return None if values is None else np.asarray(values, dtype=float)


class CliRun:
    """`nupmpc closed-loop` as a child process, its step lines stamped with their arrival
    time (the CLI flushes every line) and its stderr kept (the reconnect attempts)."""

    STEP_FIELDS = ("held", "t_s", "state")
    SUMMARY_FIELDS = ("held_steps", "reconnects", "longest_without_plan_s")

    def __init__(self, target, instance, steps, period_ms=None):
        command = [CLI_BINARY, "--server", target, "--format", "json", "closed-loop", str(instance),
                   "--steps", str(steps)]
        if period_ms is not None:
            command += ["--period_ms", str(period_ms)]
        self.command = command
        self.steps, self.summary, self.stderr, self.unparsed = [], None, [], []
        self.missing = set()  # step line fields this harness relies on that a line lacked
        self.first_step = threading.Event()
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                        stdin=subprocess.DEVNULL)
        self.readers = [threading.Thread(target=self._read_stdout, daemon=True),
                        threading.Thread(target=self._read_stderr, daemon=True)]
        for reader in self.readers:
            reader.start()

    def _read_stdout(self):
        for line in self.process.stdout:
            at = time.monotonic()
            try:
                fields = json.loads(line)
            except ValueError:
                self.unparsed.append(line.rstrip())
                continue
            if fields.get("summary"):
                self.summary = fields
                continue
            self.missing.update(f for f in self.STEP_FIELDS if f not in fields)
            self.steps.append(StepRecord(at=at, held=fields.get("held"), has_plan=fields["has_plan"],
                                         status=fields["status"], state=as_array(fields.get("state")),
                                         u0=as_array(fields.get("u0")), clock_s=fields.get("t_s"),
                                         index=fields["step"]))
            self.first_step.set()

    def _read_stderr(self):
        for line in self.process.stderr:
            self.stderr.append((time.monotonic(), line.rstrip()))

    def wait(self, timeout_s):
        """The exit code; None if it did not exit within timeout_s (then killed)."""
        try:
            code = self.process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            code = None
        self.kill()
        return code

    def kill(self):
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        for reader in self.readers:
            reader.join(timeout=5)

    def stderr_tail(self, lines=5):
        return " | ".join(text for _, text in self.stderr[-lines:])


class PacedLoop(threading.Thread):
    """A controller on the Python client: a session(spec, period=) stepped once a period
    with the states in turn (from `offset`), on a fixed grid of start times: a step that
    returns a little late (a held one returns at its period's end) is followed at once by
    the next, which keeps the loop's own timing from drifting; one over a period late
    starts a new grid (no burst to catch up). Stops after `steps` steps, or at stop(). A
    step that raises ends the loop; the error is kept."""

    def __init__(self, target, spec, states, period_s, steps=None, offset=0):
        super().__init__(daemon=True)
        self.target, self.spec, self.states = target, spec, states
        self.period_s, self.step_count, self.offset = period_s, steps, offset
        self.records, self.error = [], None
        self.session = None
        self.held_steps = self.reconnects = None  # the session's own counts, at the end
        self.first_step = threading.Event()
        self.stopped = threading.Event()

    def run(self):
        try:
            with nupmpc.connect(self.target) as client:
                self.session = client.session(self.spec, period=self.period_s)
                self._loop(self.session)
                self.held_steps = self.session.held_steps
                self.reconnects = self.session.stats.reconnects
                self.session.close()
        except Exception as error:  # the scenario reports it as a failure
            self.error = f"{type(error).__name__}: {error}"

    def _loop(self, session):
        next_at = time.monotonic()
        k = 0
        while not self.stopped.is_set() and (self.step_count is None or k < self.step_count):
            x = self.states[(self.offset + k) % len(self.states)]
            started = time.monotonic()
            plan = session.step(x)
            done = time.monotonic()
            self.records.append(StepRecord(at=done, held=plan.held, has_plan=plan.has_plan, status=plan.status,
                                           state=x, u0=plan.u0, u=plan.u if plan.has_plan else None,
                                           call_s=done - started, index=k))
            self.first_step.set()
            k += 1
            next_at += self.period_s
            if next_at < time.monotonic() - self.period_s:
                next_at = time.monotonic()
            self.stopped.wait(max(next_at - time.monotonic(), 0))

    def stop(self):
        self.stopped.set()
        if self.ident is not None:  # started
            self.join(timeout=30)


# The workload.

def tiled_instance(directory, steps):
    """masses_N30 with its 100 recorded closed-loop states repeated to `steps`, and those
    states: the CLI takes at most the recorded states' count of steps, and these states
    (each a feasible problem, recorded with plans that reach inside the input bounds) are
    known here whatever the fault did to the loop, so the state a step line reports can
    be checked against the one the CLI was given for it."""
    with open(harness.MASSES) as f:
        doc = json.load(f)
    recorded = doc["closed_loop"]["x1"]
    doc["closed_loop"] = {"T": steps, "x1": [recorded[t % len(recorded)] for t in range(steps)],
                          "description": f"masses_N30's recorded states, repeated to {steps} steps"}
    path = os.path.join(directory, "masses_N30_tiled.json")
    with open(path, "w") as f:
        json.dump(doc, f)
    return path, np.asarray(doc["closed_loop"]["x1"], dtype=float)


# The checks, shared by the scenarios.

def rounded(value, digits=3):
    return None if value is None else round(float(value), digits)


def check_cli_fields(r, run):
    r.check(not run.missing, f"step lines lack {sorted(run.missing)}")
    r.check(run.summary is not None, "no summary line")
    if run.summary is not None:
        lacking = [f for f in CliRun.SUMMARY_FIELDS if f not in run.summary]
        r.check(not lacking, f"the summary lacks {lacking}")
    r.check(not run.unparsed, f"lines that are not JSON: {run.unparsed[:3]}")


def check_states_sent(r, steps, states):
    """Each step line's state is the instance's state for that step (what the CLI sent):
    the spot check re-solves the reported state, so it must be the one sent."""
    wrong = [s.index for s in steps if s.state is not None and not np.array_equal(s.state, states[s.index])]
    if wrong:
        line = next(s for s in steps if s.index == wrong[0])
        reported = next((t for t in range(len(states)) if np.array_equal(states[t], line.state)), None)
        r.check(False, f"{len(wrong)} step lines report another state than the one sent (steps {wrong[:5]}; "
                       f"step {wrong[0]} reports the state of step {reported})")


def check_held_means_no_plan(r, steps):
    r.check(not any(s.held and s.has_plan for s in steps), "a held step carries a plan")


def check_cli_gaps(r, steps, period_s):
    """Consecutive step lines' t_s (the CLI's own clock) at most a period + slack apart."""
    clocks = [s.clock_s for s in steps if s.clock_s is not None]
    longest = max(np.diff(clocks), default=None) if len(clocks) >= 2 else None
    r.figures["longest_step_gap_s"] = rounded(longest)
    r.check(longest is not None and longest <= period_s + STEP_SLACK_S,
            f"step lines {rounded(longest)} s apart (t_s), over the period + {STEP_SLACK_S} s")


def check_python_gaps(r, steps, period_s):
    """Every step() within a period + slack, and so the steps' returns too."""
    longest_call = max((s.call_s for s in steps), default=None)
    returns = [s.at for s in steps]
    longest_gap = max(np.diff(returns), default=None) if len(returns) >= 2 else None
    r.figures["longest_step_call_s"] = rounded(longest_call)
    r.figures["longest_step_gap_s"] = rounded(longest_gap)
    r.check(longest_call is not None and longest_call <= period_s + STEP_SLACK_S,
            f"a step() took {rounded(longest_call)} s, over the period + {STEP_SLACK_S} s")
    r.check(longest_gap is not None and longest_gap <= period_s + STEP_SLACK_S,
            f"steps returned {rounded(longest_gap)} s apart, over the period + {STEP_SLACK_S} s")


def check_held_during(r, steps, window, fault_s, period_s):
    """The held steps of the outage as the controller lives it (from the fault's start in
    `window` to the first fresh plan after its end) within bounds of fault_s / period_s."""
    resumed = next((s.at for s in steps if s.at > window.end and s.fresh), math.inf)
    held = sum(1 for s in steps if s.held and window.start <= s.at <= resumed)
    least = math.floor(HELD_LEAST_SHARE * fault_s / period_s + 1e-9)
    most = math.floor((fault_s + HELD_EXTRA_S) / period_s + 1e-9)
    r.figures.update({"held_during_fault": held, "held_bounds": [least, most]})
    r.check(least <= held <= most, f"{held} held steps during the {fault_s:g} s outage, outside [{least}, {most}]")


def check_plans_again(r, steps, after, within_s, what):
    """The first fresh plan that returned after `after` did so within within_s."""
    first = next((s for s in steps if s.at > after and s.fresh), None)
    again_s = None if first is None else first.at - after
    r.figures["plans_again_after_s"] = rounded(again_s)
    r.check(again_s is not None and again_s <= within_s,
            f"no plan within {within_s} s after {what}" + (f" (the first after {again_s:.2f} s)" if first else ""))


def longest_without_plan(steps):
    """The longest time between fresh plans' returns (seconds)."""
    times = [s.at for s in steps if s.fresh]
    return max(np.diff(times), default=0.0) if len(times) >= 2 else None


def spot_check(r, target, spec, steps, label, first_after=None, least=SPOT_CHECKS):
    """A few fresh plans against a cold SolveOnce of the spec with their own step's state
    as its initial state (what the step sent, the same problem): a plan for another
    step's state (a late answer taken for the current step's) differs. Checked: the first
    fresh plan after `first_after` (the riskiest, right after an outage), then plans
    spread over the rest, those with an input inside its bounds first (an input at its
    bound is the same for many states, so it could not tell a stale plan)."""
    fresh = [s for s in steps if s.fresh and s.converged and s.state is not None and s.u0 is not None]
    chosen = []
    if first_after is not None:
        chosen += [s for s in fresh if s.at > first_after][:1]
    bound = max((np.max(np.abs(s.u0)) for s in fresh), default=0.0)
    inner = [s for s in fresh if np.min(np.abs(s.u0)) < 0.98 * bound and s not in chosen]
    pool = inner if len(inner) >= SPOT_CHECKS - len(chosen) else [s for s in fresh if s not in chosen]
    want = max(SPOT_CHECKS - len(chosen), 0)
    if pool and want:
        chosen += [pool[i] for i in sorted({round(j * (len(pool) - 1) / max(want - 1, 1)) for j in range(want)})]
    worst = 0.0
    with nupmpc.connect(target) as client:
        for s in chosen:
            cold = type(spec)()
            cold.CopyFrom(spec)
            cold.initial_state.mean[:] = s.state.tolist()
            plan = client.solve_once(cold)
            if not plan.has_plan:
                r.check(False, f"{label}: the cold solve has no plan ({plan.status})")
                continue
            ours, theirs = (s.u, plan.u) if s.u is not None else (s.u0, plan.u0)
            worst = max(worst, float(np.max(np.abs(ours - theirs))))
    r.figures[f"{label}_checked"] = len(chosen)
    r.figures[f"{label}_max_difference"] = worst
    r.check(len(chosen) >= least, f"{label}: only {len(chosen)} fresh converged plans to check, {least} wanted")
    r.check(worst <= SPOT_TOLERANCE, f"{label}: a plan differs from the cold solve of its own step's state by "
                                     f"{worst:.3g} (a plan for another state?)")


# The scenarios.

def steps_for(before_s, fault_s, after_s):
    return math.ceil((before_s + fault_s + after_s) / PERIOD_S)


class CliScenario:
    """The CLI at PERIOD_MS against one server, `make_fault(server)` applied after
    `before` seconds of steps for fault_s; check(r, run, window) adds the scenario's
    checks to the shared ones (exit 0, fields, gaps)."""

    def __init__(self, name, quick, fault_s, make_fault):
        self.r = Result(name)
        self.fault_s, self.make_fault = fault_s, make_fault
        self.before_s, self.after_s = phases(quick)

    def run(self, check):
        r = self.r
        server = harness.Server()
        directory = tempfile.mkdtemp(prefix="quiet-faults-")
        run = None
        try:
            steps = steps_for(self.before_s, self.fault_s, self.after_s)
            instance, states = tiled_instance(directory, steps)
            run = CliRun(server.target, instance, steps, period_ms=PERIOD_MS)
            if not run.first_step.wait(30):
                code = run.wait(5)
                raise harness.HarnessError(f"no step line within 30 s (exit {code}): {run.stderr_tail()}")
            fault = self.make_fault(server)
            window = inject(fault, run.steps[0].at + self.before_s, self.fault_s)
            code = run.wait(steps * PERIOD_S + 60)
            fault.report(r)
            r.figures.update({"exit_code": code, "steps": len(run.steps),
                              "held_steps": sum(1 for s in run.steps if s.held),
                              "longest_without_plan_s_seen": rounded(longest_without_plan(run.steps))})
            summary = run.summary or {}
            r.figures.update({k: summary.get(k) for k in ("reconnects", "reconnect_attempts", "longest_without_plan_s")})
            r.figures["summary_held_steps"] = summary.get("held_steps")
            r.check(code == 0, f"nupmpc exited with {code}: {run.stderr_tail()}")
            r.check(run.steps[-1].at > window.end, "the run ended before the heal")
            check_cli_fields(r, run)
            check_states_sent(r, run.steps, states)
            check_held_means_no_plan(r, run.steps)
            check_cli_gaps(r, run.steps, PERIOD_S)
            check(r, run, window, server)
        finally:
            if run is not None:
                run.kill()
            server.stop()
            shutil.rmtree(directory, ignore_errors=True)
        return r


def cli_partition(seconds):
    def scenario(quick):
        def check(r, run, window, server):
            check_held_during(r, run.steps, window, seconds, PERIOD_S)
            check_plans_again(r, run.steps, window.end, PLANS_AGAIN_WITHIN_S, "the heal")
            summary = run.summary or {}
            held = sum(1 for s in run.steps if s.held)
            r.check(summary.get("held_steps") == held,
                    f"the summary's held_steps {summary.get('held_steps')} is not the {held} held lines")
            if seconds >= 10:
                r.check((summary.get("reconnects") or 0) >= 1, "no reconnect: the dead stream was never found")
            r.check((summary.get("longest_without_plan_s") or 0) >= HELD_LEAST_SHARE * seconds,
                    f"longest_without_plan_s {summary.get('longest_without_plan_s')} is shorter than the partition")
            spec, _ = harness.masses()
            spot_check(r, server.target, spec, run.steps, "plans", first_after=window.end)
        return CliScenario(f"cli_partition_{seconds}s", quick, seconds, lambda server: Partition(server.port)).run(check)
    return scenario


def python_partition(seconds):
    def scenario(quick):
        r = Result(f"python_partition_{seconds}s")
        before_s, after_s = phases(quick)
        server = harness.Server()
        spec, states = harness.masses()
        loop = PacedLoop(server.target, spec, states, PERIOD_S, steps=steps_for(before_s, seconds, after_s))
        try:
            loop.start()
            if not loop.first_step.wait(30):
                loop.stop()
                raise harness.HarnessError(f"no step within 30 s: {loop.error}")
            fault = Partition(server.port)
            window = inject(fault, loop.records[0].at + before_s, seconds)
            loop.join(timeout=(before_s + seconds + after_s) + 60)
            steps = loop.records
            fault.report(r)
            held = sum(1 for s in steps if s.held)
            r.figures.update({"steps": len(steps), "held_steps": held, "session_held_steps": loop.held_steps,
                              "reconnects": loop.reconnects,
                              "longest_without_plan_s": rounded(longest_without_plan(steps))})
            r.check(loop.error is None, f"the loop failed: {loop.error}")
            r.check(not loop.is_alive(), "the loop did not end")
            r.check(bool(steps) and steps[-1].at > window.end, "the loop ended before the heal")
            check_held_means_no_plan(r, steps)
            check_python_gaps(r, steps, PERIOD_S)
            check_held_during(r, steps, window, seconds, PERIOD_S)
            check_plans_again(r, steps, window.end, PLANS_AGAIN_WITHIN_S, "the heal")
            r.check(loop.held_steps == held, f"session.held_steps {loop.held_steps} is not the {held} held steps")
            if seconds >= 10:
                r.check((loop.reconnects or 0) >= 1, "no reconnect: the dead stream was never found")
            r.check((longest_without_plan(steps) or 0) >= HELD_LEAST_SHARE * seconds,
                    "the longest time without a plan is shorter than the partition")
            spot_check(r, server.target, spec, steps, "plans", first_after=window.end)
        finally:
            loop.stop()
            server.stop()
        return r
    return scenario


FREEZE_S = 10.0


def frozen_server(quick):
    def check(r, run, window, server):
        check_held_during(r, run.steps, window, FREEZE_S, PERIOD_S)
        check_plans_again(r, run.steps, window.end, PLANS_AGAIN_WITHIN_S, "SIGCONT")
        spec, _ = harness.masses()
        spot_check(r, server.target, spec, run.steps, "plans", first_after=window.end)
    return CliScenario("frozen_server", quick, FREEZE_S, Freeze).run(check)


LOSS_S = 10.0


def loss(percent):
    def scenario(quick):
        def check(r, run, window, server):
            check_plans_again(r, run.steps, window.end, PLANS_AGAIN_WITHIN_S, "the loss ended")
            during = [s for s in run.steps if window.start <= s.at <= window.end]
            r.figures.update({"steps_during_loss": len(during), "held_during_loss": sum(1 for s in during if s.held),
                              "plans_during_loss": sum(1 for s in during if s.fresh)})
            spec, _ = harness.masses()
            # A 5 % loss lets most steps through: some of its plans must be there to check.
            spot_check(r, server.target, spec, during, "plans_during_loss", least=1 if percent <= 5 else 0)
        return CliScenario(f"loss_{percent}", quick, LOSS_S,
                           lambda server: Loss(server.port, percent)).run(check)
    return scenario


# Replicas behind HAProxy.

def _haproxy_stat():
    """deploy/haproxy/haproxy-stat.py as a module (its file name is not an identifier)."""
    spec = importlib.util.spec_from_file_location("haproxy_stat", HAPROXY_STAT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class Balancer:
    """HAProxy in front of `replicas` (HOST:PORT each), configured by
    deploy/haproxy/haproxy-config.sh, in the foreground (master and worker); up when it
    sees every replica UP."""

    def __init__(self, replicas, directory):
        self.target = f"{HOST}:{free_loopback_ports(1)[0]}"
        self.stats = os.path.join(directory, "haproxy.sock")
        self.show_stat = _haproxy_stat().show_stat
        config = os.path.join(directory, "haproxy.cfg")
        with open(config, "w") as f:
            f.write(run_tool([str(HAPROXY_CONFIG), "--listen", self.target, "--stats", self.stats, *replicas]))
        run_tool([HAPROXY, "-c", "-q", "-f", config])
        self.log = open(os.path.join(directory, "haproxy.log"), "w")
        self.process = subprocess.Popen([HAPROXY, "-W", "-db", "-f", config], stdout=self.log,
                                        stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        if not wait_for(lambda: set(self.statuses().values()) == {"UP"} and len(self.statuses()) == len(replicas), 20):
            raise harness.HarnessError(f"HAProxy did not see every replica UP: {self.statuses()}")

    def statuses(self):
        """{server name (r1, r2, ...): status (UP, DOWN, ...)} of the streams backend."""
        try:
            rows = self.show_stat(self.stats)
        except OSError:
            return {}
        return {row["svname"]: row["status"].split(" ")[0] for row in rows
                if row["pxname"] == "streams" and row["svname"] not in ("FRONTEND", "BACKEND")}

    def stop(self):
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()


def streams_on(server):
    return server.metric_sum("nupmpc_control_streams")


def sessions_on(server):
    """The ids of the sessions `server` holds (ListSessions, reached directly)."""
    with nupmpc.connect(server.target) as client:
        return {s.session_id for s in client.list_sessions()}


def recovery_s(records, start, end):
    """For a stream cut at `start`: seconds from `start` to its first fresh plan after its
    first held step (None: it never held, or got no plan again before `end`)."""
    first_held = next((s for s in records if s.at >= start and s.held), None)
    if first_held is None:
        return None
    again = next((s for s in records if s.at > first_held.at and s.fresh), None)
    return None if again is None or again.at > end else again.at - start


def most_missed_in_a_row(records):
    longest = run = 0
    for s in records:
        run = 0 if s.fresh else run + 1
        longest = max(longest, run)
    return longest


def streams_on_victim(r, replicas, loops):
    """The replica with the most streams (to be partitioned), and the indices of the loops
    whose sessions it holds (by id, from its ListSessions)."""
    counts = [streams_on(s) for s in replicas]
    victim = replicas[int(np.argmax(counts))]
    held_there = sessions_on(victim)
    affected = [i for i, loop in enumerate(loops) if loop.session is not None and loop.session.id in held_there]
    r.figures.update({"streams_per_replica": [int(c) for c in counts], "affected_streams": len(affected)})
    r.check(len(affected) == max(counts), "the partitioned replica's sessions are not the streams it counts")
    return victim, affected


def watch_down(balancer, name, timeout_s):
    """A thread that keeps when HAProxy first shows replica `name` as anything but UP, in
    its .down_at (a list: empty if never)."""
    down_at = []

    def watch():
        if wait_for(lambda: balancer.statuses().get(name) not in ("UP", None), timeout_s, every_s=0.1):
            down_at.append(time.monotonic())

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.down_at = down_at
    watcher.start()
    return watcher


def check_replica_partition(r, loops, affected, window, opened):
    """The streams of the partitioned replica get plans again within REPLICA_RECOVERY_S of
    the partition, while it lasts; the others (from when all were open) never miss more
    than OTHER_STREAMS_MAY_MISS periods in a row nor reconnect; no step() over the period + slack."""
    others = [i for i in range(len(loops)) if i not in affected]
    errors = [loop.error for loop in loops if loop.error]
    recoveries = [recovery_s(loops[i].records, window.start, window.end) for i in affected]
    missed = [most_missed_in_a_row([s for s in loops[i].records if s.at >= opened]) for i in others]
    longest_call = max((s.call_s for loop in loops for s in loop.records), default=None)
    r.figures.update({
        "affected_plans_again_after_s": [rounded(x) for x in recoveries],
        "others_most_periods_missed_in_a_row": max(missed, default=None),
        "longest_step_call_s": rounded(longest_call),
        "reconnects_affected": sum(loops[i].reconnects or 0 for i in affected),
        "reconnects_others": sum(loops[i].reconnects or 0 for i in others),
        "held_steps_affected": sum(1 for i in affected for s in loops[i].records if s.held),
        "held_steps_others": sum(1 for i in others for s in loops[i].records if s.held)})
    r.check(not errors, f"{len(errors)} streams failed: {errors[:3]}")
    r.check(len(affected) >= 1, "no stream was on the partitioned replica")
    r.check(all(x is not None and x <= REPLICA_RECOVERY_S for x in recoveries),
            f"a stream of the partitioned replica got no plan again within {REPLICA_RECOVERY_S} s of the partition")
    r.check(max(missed, default=0) <= OTHER_STREAMS_MAY_MISS,
            f"a stream of a healthy replica missed {max(missed, default=0)} periods in a row")
    r.check(r.figures["reconnects_others"] == 0, "a stream of a healthy replica reconnected")
    r.check(longest_call is not None and longest_call <= PERIOD_S + STEP_SLACK_S,
            f"a step() took {rounded(longest_call)} s, over the period + {STEP_SLACK_S} s")


def haproxy_replica_partition(quick):
    r = Result("haproxy_replica_partition")
    partition_s = 12.0 if quick else 30.0
    settle_s, after_s = (2.0, 3.0) if quick else (5.0, 10.0)
    directory = tempfile.mkdtemp(prefix="quiet-faults-")
    replicas, balancer, loops = [], None, []
    try:
        # --list_all_sessions: ListSessions (sessions_on) shows every connection's sessions,
        # HAProxy's included, not only those of the connection that asks.
        for _ in range(REPLICAS):
            replicas.append(harness.Server("--log_level", "warn", "--list_all_sessions"))
        balancer = Balancer([s.target for s in replicas], directory)
        spec, states = harness.masses()
        loops = [PacedLoop(balancer.target, spec, states, PERIOD_S, offset=7 * i) for i in range(STREAMS_BEHIND_HAPROXY)]
        for loop in loops:
            loop.start()
        if not wait_for(lambda: sum(streams_on(s) for s in replicas) == STREAMS_BEHIND_HAPROXY, 30):
            raise harness.HarnessError(f"the streams never all opened: errors {[l.error for l in loops if l.error]}")
        opened = time.monotonic()
        time.sleep(settle_s)
        victim, affected = streams_on_victim(r, replicas, loops)
        # Only the replica's port: HAProxy's connections to the others, and the clients'
        # to HAProxy, stay up.
        fault = Partition(victim.port)
        watcher = watch_down(balancer, f"r{replicas.index(victim) + 1}", partition_s)
        window = inject(fault, time.monotonic(), partition_s)
        watcher.join(timeout=5)
        time.sleep(after_s)
        for loop in loops:
            loop.stop()
        fault.report(r)
        r.figures["balancer_saw_it_down_after_s"] = (rounded(watcher.down_at[0] - window.start)
                                                     if watcher.down_at else None)
        check_replica_partition(r, loops, affected, window, opened)
    finally:
        for loop in loops:
            loop.stop()
        if balancer is not None:
            balancer.stop()
        for server in replicas:
            server.stop()
        shutil.rmtree(directory, ignore_errors=True)
    return r


SCENARIOS = {
    **{f"cli_partition_{s}s": cli_partition(s) for s in (2, 10, 60)},
    **{f"python_partition_{s}s": python_partition(s) for s in (2, 10, 60)},
    "frozen_server": frozen_server,
    "loss_5": loss(5), "loss_30": loss(30),
    "haproxy_replica_partition": haproxy_replica_partition,
}


# Running them: one child process per scenario, each in its own network namespace.

def run_one(name, quick):
    """In the namespace: the scenario's Result line on stdout; exit 1 when it failed."""
    started = time.monotonic()
    try:
        result = SCENARIOS[name](quick)
    except Exception as error:  # a scenario that cannot run is a failed one, with its reason
        result = Result(name)
        result.check(False, f"{type(error).__name__}: {error}")
    result.figures["scenario_s"] = round(time.monotonic() - started, 1)
    print(result.line(), flush=True)
    return 1 if result.failures else 0


class Child:
    """One scenario re-executed in a new network namespace; its process group is its own,
    so that a child that overruns is ended with everything it started."""

    def __init__(self, name, quick):
        self.name = name
        args = [name] + (["--quick"] if quick else [])
        self.process = subprocess.Popen(namespaced_command(__file__, own_network_namespace(), *args),
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                        start_new_session=True)
        self.deadline = time.monotonic() + CHILD_TIMEOUT_S

    def finish(self):
        """Its report (the Result line, or a FAIL saying why there is none) and whether it passed."""
        try:
            out, err = self.process.communicate(timeout=max(self.deadline - time.monotonic(), 0))
            why = f"exited with {self.process.returncode} without a result"
        except subprocess.TimeoutExpired:
            self.kill()
            out, err = self.process.communicate()
            why = f"did not finish within {CHILD_TIMEOUT_S} s"
        if out.startswith(("PASS ", "FAIL ")):
            return out.rstrip(), out.startswith("PASS ") and self.process.returncode == 0
        failed = Result(self.name)
        failed.check(False, f"{why}; stderr: {err.strip()[-1500:]}")
        return failed.line(), False

    def kill(self):
        try:
            os.killpg(self.process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def run_all(names, quick, jobs):
    """Runs the scenarios, `jobs` at a time, printing each report as it is done; the
    number that failed."""
    for tool in (UNSHARE, NFT, IP):
        if not os.access(tool, os.X_OK):
            raise harness.HarnessError(f"{tool} is missing: deploy/install-deps.sh installs it")
    waiting, running, failed = list(names), [], 0
    try:
        while waiting or running:
            while waiting and len(running) < jobs:
                running.append(Child(waiting.pop(0), quick))
            done = next((c for c in running if c.process.poll() is not None), None)
            if done is None:
                overdue = next((c for c in running if time.monotonic() > c.deadline), None)
                if overdue is None:
                    time.sleep(0.2)
                    continue
                done = overdue
            running.remove(done)
            line, passed = done.finish()
            print(line, flush=True)
            failed += not passed
    finally:
        for child in running:
            child.kill()
    return failed


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter phases around the faults (the ctests)")
    parser.add_argument("--jobs", type=int, default=0, help="scenarios at once (default: all given)")
    parser.add_argument("--in_namespace", help=argparse.SUPPRESS)  # the re-executed child: the namespace it left
    parser.add_argument("scenarios", nargs="*", help=f"of {', '.join(SCENARIOS)} (default: all)")
    args = parser.parse_args()
    unknown = [n for n in args.scenarios if n not in SCENARIOS]
    if unknown:
        parser.error(f"unknown scenario {unknown[0]}: one of {', '.join(SCENARIOS)}")
    if args.in_namespace:
        if len(args.scenarios) != 1:
            parser.error("--in_namespace runs exactly one scenario")
        try:
            enter_namespace(args.in_namespace)
        except Exception as error:
            failed = Result(args.scenarios[0])
            failed.check(False, f"{type(error).__name__}: {error}")
            print(failed.line(), flush=True)
            return 1
        return run_one(args.scenarios[0], args.quick)
    # ctest ends an overrunning test with SIGTERM: end the children's process groups too.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    names = args.scenarios or list(SCENARIOS)
    try:
        failed = run_all(names, args.quick, args.jobs if args.jobs > 0 else len(names))
    except harness.HarnessError as error:
        print(f"quiet_faults: FAIL: {error}")
        return 1
    print(f"quiet_faults: {'FAIL' if failed else 'PASS'} ({failed} of {len(names)} failed)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
