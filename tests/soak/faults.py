#!/usr/bin/python3
"""Fault scenarios against the real nupmpc-server binary, each with its own
server process, a PASS/FAIL line and its figures:

  restart      SIGKILL and restart under 32 live Control streams (nupmpc-scaleout-probe,
               the client library): every stream re-creates its session, no step fails,
               and every resent step's plan equals the core's solve of that step's state
  sigterm      SIGTERM with solves in flight: exit 0, every in-flight request answered
  slow_reader  a client that sends steps and never reads: the server stops reading it
               (memory bounded), other streams keep being served
  idle         1,000 idle connections (half silent TCP, half HTTP/2 without calls) and 500
               Control streams that never send (build/bin/silent_streams, a test helper):
               all ended by the server's timeouts
  killed       a client killed mid-solve: the solve is cancelled, the worker free at once
  frozen_client  a client stopped (SIGSTOP) with its Control stream open: the server's
               keepalive pings find it and end the stream, closing its session, within
               --keepalive_time_s + --keepalive_timeout_s
  frozen_server  the server stopped (SIGSTOP) while a client waits for a plan: the client's
               keepalive pings find it and the step fails with UNAVAILABLE within about 4 s
  slow_loris   connections holding half a gRPC message or half an HTTP/2 frame: ended and
               closed, others served meanwhile
  fair_share   64 Control streams on one worker and one CPU (nupmpc-loadtest): every stream
               served within a factor 2 of the mean

    tests/soak/faults.py [--quick] [SCENARIO ...]

Exit 1 when any scenario fails. --quick: shorter phases (the ctest Faults.Quick)."""

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter

import grpc

import harness
import raw_http2
from harness import nupmpc, pb, percentile
from nupmpc._proto import pb_grpc
from nupmpc.security import channel_options

BIN = harness.REPO / "build" / "bin"
PROBE_BINARY = os.environ.get("NUPMPC_PROBE_BINARY", str(BIN / "nupmpc-scaleout-probe"))
SILENT_STREAMS_BINARY = os.environ.get("NUPMPC_SILENT_STREAMS_BINARY", str(BIN / "silent_streams"))
CLI_BINARY = os.environ.get("NUPMPC_CLI_BINARY", str(BIN / "nupmpc"))
LOADTEST_BINARY = os.environ.get("NUPMPC_LOADTEST_BINARY", str(BIN / "nupmpc-loadtest"))
# The slowest benchmark solve: long enough to signal or kill a client in the middle of it.
LONG_SOLVE = harness.BENCHMARKS / "random_outbox_M40_K20_L20_N1000_s1.json"
FIRST_MESSAGE_TIMEOUT_S = 2.0
CONNECTION_IDLE_TIMEOUT_S = 2.0
# The idle scenario's silent streams end after FIRST_MESSAGE_TIMEOUT_S; their client gives up
# on them (a deadline of its own) long after.
SILENT_STREAMS_GIVE_UP_S = FIRST_MESSAGE_TIMEOUT_S + 30
NO_RECONNECT = nupmpc.ReconnectOptions(budget_s=0)


class Result:
    def __init__(self, name):
        self.name, self.failures, self.figures = name, [], {}

    def check(self, ok, what):
        if not ok:
            self.failures.append(what)

    def line(self):
        return f"{'PASS' if not self.failures else 'FAIL'} {self.name}: {json.dumps(self.figures)}" + \
            "".join(f"\n  FAIL: {f}" for f in self.failures)


def wait_for(condition, timeout_s, every_s=0.02):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(every_s)
    return condition()


class Stepper(threading.Thread):
    """A well-behaved controller stepping masses_N30 until stopped: its round trips with
    their start times, and its errors by code."""

    def __init__(self, target):
        super().__init__(daemon=True)
        self.target = target
        self.spec, self.states = harness.masses()
        self.samples, self.errors = [], Counter()
        self.stopped = threading.Event()

    def run(self):
        with nupmpc.connect(self.target) as client:
            session = client.session(self.spec, reconnect=NO_RECONNECT)
            t = 0
            while not self.stopped.is_set():
                start = time.monotonic()
                try:
                    session.step(self.states[t % len(self.states)])
                    self.samples.append((start, (time.monotonic() - start) * 1e3))
                except nupmpc.NupmpcError as error:
                    self.errors[error.code.name] += 1
                    return
                t += 1
            session.close()

    def between(self, start, end):
        return [ms for t, ms in self.samples if start <= t < end]

    def stop(self):
        self.stopped.set()
        self.join(timeout=30)


def restart(quick):
    r = Result("restart")
    server = harness.Server("--threads", "2")
    probe = None
    try:
        # The probe steps until the streams are back and stepped on for a while (SIGTERM ends
        # it; its duration only bounds a hung run), however slow the machine.
        after_s = 2 if quick else 10
        probe = subprocess.Popen([PROBE_BINARY, "--server", server.target, "--instance", str(harness.MASSES),
                                  "--probe", "streams", "--streams", "32",
                                  "--duration_s", "600", "--verify_every", "25"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        r.check(wait_for(lambda: server.metric_sum("nupmpc_control_streams") == 32, 20), "32 streams never opened")
        time.sleep(1.0)
        killed_at = time.monotonic()
        server.kill()
        server.start()
        r.figures["restart_s"] = round(time.monotonic() - killed_at, 3)
        r.check(wait_for(lambda: server.metric_sum("nupmpc_control_streams") == 32, 30),
                "the 32 streams did not come back to the new server")
        time.sleep(after_s)
        probe.terminate()
        out, err = probe.communicate(timeout=120)
        if probe.returncode != 0:
            raise harness.HarnessError(f"nupmpc-scaleout-probe exited with {probe.returncode}: {err[-500:]}")
        report = json.loads(out)
        r.figures.update({k: report[k] for k in ("steps", "failed_steps", "no_plan", "reconnects", "longest_outage_s",
                                                 "verified", "mismatched", "max_plan_difference")})
        r.figures["sessions_on_new_server"] = server.metric_sum("nupmpc_sessions_created_total")
        r.check(report["reconnects"] == 32, "not every stream re-created its session exactly once")
        r.check(report["failed_steps"] == 0, "steps failed")
        r.check(report["mismatched"] == 0, "a plan differs from the core's solve of its own state (stale)")
        r.check(report["verified"] >= 32, "fewer checked plans than resent steps")
    finally:
        if probe is not None and probe.poll() is None:
            probe.kill()
            probe.wait()
        server.stop()
    return r


def sigterm(quick):
    r = Result("sigterm")
    server = harness.Server("--threads", "2", "--grace_period_s", "30")
    spec, states = harness.masses()
    long_spec = nupmpc.load_instance(LONG_SOLVE).spec
    one_offs, stream_outcomes = [], Counter()
    signalled_at = [float("inf")]
    waiting_since = [None] * 8  # per stream: when its unanswered step was sent

    def one_off():
        with nupmpc.connect(server.target) as client:
            try:
                plan = client.solve_once(long_spec)
                one_offs.append("plan" if plan.has_plan else f"no plan ({plan.status})")
            except nupmpc.NupmpcError as error:
                one_offs.append(f"{error.code.name}: {error.details}")

    def stream(index):
        with nupmpc.connect(server.target) as client:
            session = client.session(spec, reconnect=NO_RECONNECT)
            t = index
            while True:
                sent_at = time.monotonic()
                waiting_since[index] = sent_at
                try:
                    plan = session.step(states[t % len(states)])
                    waiting_since[index] = None
                    in_flight = sent_at < signalled_at[0] < time.monotonic()
                    stream_outcomes["plans" if not in_flight else "in flight at the signal: plan"] += plan.has_plan
                except nupmpc.NupmpcError as error:
                    # The server's own answer to a step sent after the signal is "shutting
                    # down"; a step in flight at the signal must get its plan; anything
                    # else is a call the drain broke.
                    refused = "shutting down" in error.details and sent_at > signalled_at[0]
                    stream_outcomes["refused after the signal" if refused else f"broken: {error.code.name}: {error.details[:80]} (sent {sent_at - signalled_at[0]:+.3f} s)"] += 1
                    return
                t += 1

    try:
        # Streams first: a session is built on the worker pool, behind the long solves.
        workers = [threading.Thread(target=stream, args=(i,)) for i in range(8)]
        for w in workers:
            w.start()
        r.check(wait_for(lambda: server.metric_sum("nupmpc_active_sessions") == 8, 30), "the streams never opened")
        # Three long solves on two workers: every stream's next step waits behind them, so
        # the pool holds 11 tasks (one per stream, three solves) once all have arrived.
        workers += [threading.Thread(target=one_off) for _ in range(3)]
        for w in workers[8:]:
            w.start()
        # The metrics can add up to 11 a moment before the last stream's step is held too (a
        # stream still stepping would send its next step at the signal, which the server may
        # receive after it and rightly refuse): also wait until every stream's step has been
        # unanswered for far longer than a step takes.
        def all_held():
            now = time.monotonic()
            return (server.metric_sum("nupmpc_workers_busy") + server.metric_sum("nupmpc_queue_depth") == 11 and
                    all(since is not None and now - since > 0.05 for since in waiting_since))
        r.check(wait_for(all_held, 30), "the solves and steps never all reached the server")
        signalled_at[0] = time.monotonic()
        exit_code = server.terminate(timeout_s=60)
        r.figures["drain_s"] = round(time.monotonic() - signalled_at[0], 2)
        for w in workers:
            w.join(timeout=30)
        r.figures.update({"exit_code": exit_code, "solve_once": dict(Counter(one_offs)),
                          "streams": dict(stream_outcomes)})
        r.check(exit_code == 0, f"exit code {exit_code}")
        r.check(one_offs.count("plan") == 3, "an in-flight SolveOnce was not answered with its plan")
        r.check(not any(k.startswith("broken") for k in stream_outcomes), "a stream broke instead of being answered")
        r.check(stream_outcomes["in flight at the signal: plan"] == 8, "a stream's step in flight was not answered")
        r.check(stream_outcomes["refused after the signal"] == 8, "not every stream was told the server shuts down")
    finally:
        server.stop()
    return r


def slow_reader(quick):
    r = Result("slow_reader")
    server = harness.Server("--threads", "2")
    spec, states = harness.masses()
    phase_s = 2 if quick else 10
    others = [Stepper(server.target) for _ in range(4)]
    stop_writing = threading.Event()
    written = Counter()

    def requests():
        yield pb.ControlRequest(sequence=1, spec=spec)
        t = 2
        while not stop_writing.is_set():
            yield pb.ControlRequest(sequence=t, step=pb.Step(state=states[t % len(states)].tolist()))
            written["steps"] += 1
            t += 1

    try:
        for o in others:
            o.start()
        time.sleep(phase_s)
        rss_before = server.rss_bytes()
        baseline_end = time.monotonic()
        channel = grpc.insecure_channel(server.target, options=channel_options(None, True))
        call = pb_grpc.MpcServiceStub(channel).Control(requests())  # its answers are never read
        rss_max = rss_before
        while time.monotonic() < baseline_end + phase_s:
            rss_max = max(rss_max, server.rss_bytes())
            time.sleep(0.1)
        held_end = time.monotonic()
        written_while_held = written["steps"]
        pauses = server.metric_sum("nupmpc_control_stream_read_pauses_total")
        for o in others:
            o.stop()
        stop_writing.set()
        call.cancel()
        channel.close()
        before = [ms for o in others for ms in o.between(0, baseline_end)]
        during = [ms for o in others for ms in o.between(baseline_end, held_end)]
        r.figures.update({
            "rss_before_mib": round(rss_before / 2**20, 1), "rss_max_while_held_mib": round(rss_max / 2**20, 1),
            "slow_reader_steps_written": written_while_held, "read_pauses": pauses,
            "others_steps_before": len(before), "others_steps_during": len(during),
            "others_p50_ms_before": round(percentile(before, 50), 3), "others_p50_ms_during": round(percentile(during, 50), 3),
            "others_p99_ms_before": round(percentile(before, 99), 3), "others_p99_ms_during": round(percentile(during, 99), 3),
            "others_errors": dict(sum((o.errors for o in others), Counter()))})
        r.check(pauses >= 1, "the server never stopped reading the slow reader")
        r.check(rss_max - rss_before < 32 * 2**20, "server memory grew by 32 MiB or more while the client did not read")
        r.check(all(len(o.between(baseline_end, held_end)) > 0 for o in others), "another stream was starved")
        r.check(not any(o.errors for o in others), "another stream saw an error")
    finally:
        server.stop()
    return r


def silent_streams(target, count, outcomes, failures):
    """`count` Control calls that never send, from SILENT_STREAMS_BINARY (gRPC's C++ client);
    appends how each ended, (code name, details), to `outcomes`, or why there is no answer to
    `failures`. Calls the server never ends end at the helper's own deadline."""
    try:
        done = subprocess.run([SILENT_STREAMS_BINARY, target, str(count), "100", str(SILENT_STREAMS_GIVE_UP_S)],
                              capture_output=True, text=True, timeout=SILENT_STREAMS_GIVE_UP_S + 15)
    except subprocess.TimeoutExpired as hung:
        failures.append(f"silent_streams did not exit {SILENT_STREAMS_GIVE_UP_S + 15} s after it started; "
                        f"stderr: {(hung.stderr or b'')[-2000:]!r}")
        return
    except OSError as error:
        failures.append(f"silent_streams could not run ({SILENT_STREAMS_BINARY}): {error}")
        return
    if done.returncode != 0:
        failures.append(f"silent_streams exited with {done.returncode}: {done.stderr[-2000:]}")
        return
    outcomes.extend(tuple(pair) for pair in json.loads(done.stdout))


def timeout_flags():
    return ("--first_message_timeout_s", str(FIRST_MESSAGE_TIMEOUT_S),
            "--connection_idle_timeout_s", str(CONNECTION_IDLE_TIMEOUT_S))


def idle(quick):
    r = Result("idle")
    server = harness.Server("--threads", "2", *timeout_flags())
    try:
        fds_before, rss_before = server.open_fds(), server.rss_bytes()
        tcp = [raw_http2.connect(server.port, handshake=False) for _ in range(500)]
        h2 = [raw_http2.connect(server.port, handshake=True) for _ in range(500)]
        outcomes, failures = [], []
        streams = threading.Thread(target=silent_streams, args=(server.target, 500, outcomes, failures))
        streams.start()
        opened = wait_for(lambda: server.metric_sum("nupmpc_control_streams") == 500, FIRST_MESSAGE_TIMEOUT_S)
        fds_held, rss_held = server.open_fds(), server.rss_bytes()
        served = Stepper(server.target)
        served.start()
        closed, last_close_s = raw_http2.closed_by_peer(tcp + h2, FIRST_MESSAGE_TIMEOUT_S + CONNECTION_IDLE_TIMEOUT_S + 15)
        streams.join(timeout=SILENT_STREAMS_GIVE_UP_S + 20)
        streams_open_after = server.metric_sum("nupmpc_control_streams")
        served.stop()
        for s in tcp + h2:
            s.close()
        wait_for(lambda: server.open_fds() <= fds_before + 10, 10)
        codes = Counter(code for code, _ in outcomes)
        r.figures.update({
            "fds_before": fds_before, "fds_held": fds_held, "fds_after": server.open_fds(),
            "rss_before_mib": round(rss_before / 2**20, 1), "rss_held_mib": round(rss_held / 2**20, 1),
            "rss_after_mib": round(server.rss_bytes() / 2**20, 1), "connections_closed_by_server": closed,
            "last_closed_after_s": round(last_close_s, 2), "silent_streams_open_at_once": opened,
            "silent_stream_endings": dict(codes),
            "control_streams_open_after_with_the_other_clients": streams_open_after,
            "other_client_steps": len(served.samples),
            "other_client_errors": dict(served.errors)})
        r.check(closed == 1000, f"only {closed} of 1000 idle connections were closed by the server")
        for failure in failures:
            r.check(False, failure)
        r.check(codes["DEADLINE_EXCEEDED"] == 500 and all("first_message_timeout_s" in d for _, d in outcomes),
                "not every silent stream was ended naming first_message_timeout_s")
        r.check(server.open_fds() <= fds_before + 10, "file descriptors were not given back")
        r.check(len(served.samples) > 0 and not served.errors, "a well-behaved client was not served meanwhile")
    finally:
        server.stop()
    return r


def killed(quick):
    r = Result("killed")
    server = harness.Server("--threads", "1")  # one worker: a stuck one would block the next solve
    try:
        with nupmpc.connect(server.target) as client:
            full_ms = client.solve_once(nupmpc.load_instance(LONG_SOLVE).spec).solve_ms
            victim = subprocess.Popen([CLI_BINARY, "--server", server.target, "solve", str(LONG_SOLVE)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            r.check(wait_for(lambda: server.metric_sum("nupmpc_workers_busy") == 1, 30), "the victim's solve never started")
            victim.kill()
            victim.wait()
            killed_at = time.monotonic()
            spec, _ = harness.masses()
            next_plan = client.solve_once(spec)
            next_round_trip_ms = (time.monotonic() - killed_at) * 1e3
            cancelled = server.metric_sum("nupmpc_solves_total", status="cancelled")
        r.figures.update({"uncancelled_solve_ms": round(full_ms, 1), "next_solve_round_trip_ms": round(next_round_trip_ms, 1),
                          "cancelled_solves": cancelled, "next_has_plan": next_plan.has_plan})
        r.check(cancelled == 1, "the killed client's solve was not cancelled")
        r.check(next_plan.has_plan, "the next solve has no plan")
        r.check(next_round_trip_ms < 0.5 * full_ms, "the next solve waited for the killed client's solve")
    finally:
        server.stop()
    return r


# The frozen client: a controller whose process stops (SIGSTOP, a frozen VM) with its
# Control stream open and idle. Its kernel still acknowledges every TCP segment, so no TCP
# timer ever ends the connection; only the server's HTTP/2 keepalive pings, unanswered,
# show that nobody is there. The server must end the stream, and so close the session the
# stream owned, within --keepalive_time_s + --keepalive_timeout_s (plus gRPC's timer
# granularity); the slack here is for a loaded machine.
FROZEN_KEEPALIVE_S = 1.0
FROZEN_DETECTION_SLACK_S = 10.0
FROZEN_CLIENT = """
import sys, time
sys.path[:0] = sys.argv[3:]
import nupmpc
instance = nupmpc.load_instance(sys.argv[2])
with nupmpc.connect(sys.argv[1]) as client:
    session = client.session(instance.spec, reconnect=nupmpc.ReconnectOptions(budget_s=0))
    session.step(instance.closed_loop_states[0])
    print("stepped", flush=True)
    time.sleep(3600)
"""


def frozen_client(quick):
    r = Result("frozen_client")
    keepalive = str(FROZEN_KEEPALIVE_S)
    server = harness.Server("--keepalive_time_s", keepalive, "--keepalive_timeout_s", keepalive)
    victim = None
    try:
        victim = subprocess.Popen([sys.executable, "-c", FROZEN_CLIENT, server.target, str(harness.MASSES), *sys.path],
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        r.check(victim.stdout.readline().strip() == "stepped", "the client never stepped")
        r.check(server.metric_sum("nupmpc_control_streams") == 1, "the client's Control stream is not open")
        victim.send_signal(signal.SIGSTOP)
        frozen_at = time.monotonic()
        bound_s = 2 * FROZEN_KEEPALIVE_S
        ended = wait_for(lambda: server.metric_sum("nupmpc_control_streams") == 0, bound_s + FROZEN_DETECTION_SLACK_S)
        detected_s = time.monotonic() - frozen_at
        r.figures.update({"keepalive_time_s": FROZEN_KEEPALIVE_S, "keepalive_timeout_s": FROZEN_KEEPALIVE_S,
                          "stream_ended_after_s": round(detected_s, 2) if ended else None,
                          "sessions_left": server.metric_sum("nupmpc_active_sessions")})
        r.check(ended, f"the frozen client's stream was still open {bound_s + FROZEN_DETECTION_SLACK_S:.0f} s "
                       "after it froze")
        r.check(wait_for(lambda: server.metric_sum("nupmpc_active_sessions") == 0, 10),
                "the session the frozen stream owned was not closed")
        keepalive_ends = server.metric_sum("nupmpc_control_stream_ends_total", cause="keepalive")
        r.figures["stream_ends_by_keepalive"] = keepalive_ends
        r.check(keepalive_ends == 1, f"nupmpc_control_stream_ends_total{{cause=\"keepalive\"}} is {keepalive_ends}, not 1")
    finally:
        if victim is not None:
            victim.send_signal(signal.SIGCONT)
            victim.kill()
            victim.wait()
        server.stop()
    return r


# The frozen server: the server's process stops (SIGSTOP) while a client waits for a plan.
# Its kernel still acknowledges TCP, so only the client's keepalive pings (2 s, answered
# within 2 s: client/python/nupmpc/security.py) find that nobody answers: the waiting step
# fails with UNAVAILABLE within about 4 s instead of waiting for as long as the freeze lasts.
CLIENT_KEEPALIVE_BOUND_S = 4.0


def frozen_server(quick):
    r = Result("frozen_server")
    server = harness.Server()
    frozen = False
    try:
        with nupmpc.connect(server.target) as client:
            spec, states = harness.masses()
            session = client.session(spec, reconnect=NO_RECONNECT)
            session.step(states[0])
            outcome = {}

            def step_while_frozen():
                try:
                    session.step(states[1])
                    outcome["plan"] = True
                except nupmpc.NupmpcError as error:
                    outcome["code"] = error.code.name
                outcome["after_s"] = time.monotonic() - frozen_at

            os.kill(server.pid, signal.SIGSTOP)
            frozen, frozen_at = True, time.monotonic()
            waiting = threading.Thread(target=step_while_frozen, daemon=True)
            waiting.start()
            waiting.join(CLIENT_KEEPALIVE_BOUND_S + FROZEN_DETECTION_SLACK_S)
            r.figures.update({"step_ended_after_s": round(outcome["after_s"], 2) if "after_s" in outcome else None,
                              "code": outcome.get("code")})
            r.check("after_s" in outcome, f"the step still waited {CLIENT_KEEPALIVE_BOUND_S + FROZEN_DETECTION_SLACK_S:.0f} s "
                                          "after the server froze")
            r.check(outcome.get("code") == "UNAVAILABLE", f"the step ended with {outcome}, not UNAVAILABLE")
    finally:
        if frozen:
            os.kill(server.pid, signal.SIGCONT)
        server.stop()
    return r


def slow_loris(quick):
    r = Result("slow_loris")
    server = harness.Server("--threads", "2", *timeout_flags())
    try:
        fds_before = server.open_fds()
        held = []
        for i in range(100):
            s = raw_http2.connect(server.port)
            raw_http2.open_stream(s, 1, server.port)
            if i % 2 == 0:
                raw_http2.send_partial_message(s, 1)
            else:
                raw_http2.send_partial_frame(s, 1)
            held.append(s)
        wait_for(lambda: server.metric_sum("nupmpc_control_streams") == 100, FIRST_MESSAGE_TIMEOUT_S)
        streams_held = server.metric_sum("nupmpc_control_streams")
        fds_held = server.open_fds()
        served = Stepper(server.target)
        served.start()
        closed, last_close_s = raw_http2.closed_by_peer(held, FIRST_MESSAGE_TIMEOUT_S + CONNECTION_IDLE_TIMEOUT_S + 15)
        served.stop()
        for s in held:
            s.close()
        ended = server.metric_sum("nupmpc_rpc_errors_total", method="Control", code="DEADLINE_EXCEEDED")
        r.figures.update({"streams_held": streams_held, "fds_before": fds_before, "fds_held": fds_held,
                          "streams_ended_deadline_exceeded": ended, "connections_closed_by_server": closed,
                          "last_closed_after_s": round(last_close_s, 2), "other_client_steps": len(served.samples),
                          "other_client_p50_ms": round(percentile([ms for _, ms in served.samples], 50), 3),
                          "other_client_errors": dict(served.errors)})
        r.check(closed == 100, f"only {closed} of 100 slow-loris connections were closed by the server")
        r.check(ended == 100, "not every held stream was ended by the first-message timeout")
        r.check(len(served.samples) > 0 and not served.errors, "a well-behaved client was not served meanwhile")
    finally:
        server.stop()
    return r


def fair_share(quick):
    """The schedule on which an unfair drain rule starves a stream: many more streams than
    workers, one worker, the server pinned to one CPU and the load generator to another, so
    that a gRPC thread that solves steps in place competes with the worker for the same core."""
    r = Result("fair_share")
    cpus = sorted(os.sched_getaffinity(0))
    pinned = len(cpus) >= 2
    server = harness.Server("--threads", "1", "--log_level", "warn", cpus={cpus[0]} if pinned else None)
    try:
        levels = 4 if quick else 8
        command = [LOADTEST_BINARY, "--server", server.target, "--instance", str(harness.MASSES),
                   "--sweep", ",".join(["64"] * levels), "--duration_s", "2", "--echo=false", "--json",
                   "--progress", "off", "--baseline_rounds", "2", "--transport_calls", "200"]
        if pinned:
            command += ["--server_cpus", str(cpus[0]), "--client_cpus", str(cpus[1])]
        run = subprocess.run(command, capture_output=True, text=True, timeout=120 + 10 * levels)
        # Exit status 3: a level starved a stream (the JSON is printed all the same).
        if run.returncode not in (0, 3):
            raise harness.HarnessError(f"nupmpc-loadtest exited with {run.returncode}: {run.stderr[-500:]}")
        report = json.loads(run.stdout)
        least = [level["stream_min_share"] for level in report["levels"]]
        most = [level["stream_max_share"] for level in report["levels"]]
        r.figures.update({"pinned": pinned, "levels": levels,
                          "solves_per_s": [round(level["solves_per_s"]) for level in report["levels"]],
                          "least_served_share": [round(x, 2) for x in least],
                          "most_served_share": [round(x, 2) for x in most]})
        r.check(all(not level["errors"] for level in report["levels"]), "steps failed")
        r.check(min(least) >= 0.5, "a stream got under half the mean of the solves")
        r.check(max(most) <= 2.0, "a stream got over twice the mean of the solves")
        r.check(run.returncode == 0, f"nupmpc-loadtest reported starvation: {run.stderr.strip()[-500:]}")
    finally:
        server.stop()
    return r


SCENARIOS = {"restart": restart, "sigterm": sigterm, "slow_reader": slow_reader, "idle": idle, "killed": killed,
             "frozen_client": frozen_client, "frozen_server": frozen_server, "slow_loris": slow_loris, "fair_share": fair_share}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter phases (the ctest)")
    parser.add_argument("scenarios", nargs="*", help=f"of {', '.join(SCENARIOS)} (default: all)")
    args = parser.parse_args()
    unknown = [n for n in args.scenarios if n not in SCENARIOS]
    if unknown:
        parser.error(f"unknown scenario {unknown[0]}: one of {', '.join(SCENARIOS)}")
    failed = 0
    for name in args.scenarios or SCENARIOS:
        started = time.monotonic()
        try:
            result = SCENARIOS[name](args.quick)
        except Exception as error:  # a scenario that cannot run is a failed one, with its reason
            result = Result(name)
            result.check(False, f"{type(error).__name__}: {error}")
        result.figures["scenario_s"] = round(time.monotonic() - started, 1)
        print(result.line(), flush=True)
        failed += bool(result.failures)
    print(f"faults: {'FAIL' if failed else 'PASS'} ({failed} failed)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
