#!/usr/bin/env python3
"""What slow clients, a large body and many headers do to the operator HTTP endpoint.

Starts a real nupmpc-server with --metrics_address on a loopback port and attacks that
port (GET /metrics, /healthz, /readyz) the way a misbehaving or hostile client on the
operator network could:
  slow N     N connections that send the start of a request head and then one byte a
             second, never finishing it (reopened when the server closes them); meanwhile
             10 GET /healthz and 5 GET /metrics on fresh connections, 0.5 s apart
  body       POST /metrics with a Content-Length of --body_mib MiB, the body sent as fast
             as the socket takes it; the server's RSS before, after and at its peak
  headers    one request with 10,000 header lines
and prints a Markdown table with a verdict against the targets: with 300 slow connections
/healthz and /metrics answer within 1 s, and the server's peak RSS (VmHWM) while it takes the
body grows by at most 50 MiB (RSS after the body says nothing: a server that buffered the
body whole has freed it again by then).
A measurement program, not a test: it exits 0 whatever it measures.

  deploy/metrics-port-probe.py --server build/bin/nupmpc-server [--slow 8,64,300] [--body_mib 256]
"""
import argparse
import os
import resource
import select
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

HOST = "127.0.0.1"
MIB = 1 << 20
TIMEOUT_S = 10.0       # a probe with no full response within this counts as a timeout
TARGET_MS = 1000.0     # /healthz and /metrics under TARGET_SLOW slow connections
TARGET_SLOW = 300
TARGET_RSS_MIB = 50.0  # RSS growth allowed by the large body
SLOW_PREFIX = b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: "


def free_port() -> int:
    # A port from the kernel's ephemeral range: another process's outgoing connection could take
    # it before the server binds it (tests/util/loopback_port.py avoids that), unlikely enough
    # for a one-off measurement, and the server's start fails loudly if it happens.
    with socket.socket() as s:
        s.bind((HOST, 0))
        port: int = s.getsockname()[1]
        return port


@dataclass
class Reply:
    latency_s: Optional[float]  # None: no full response
    status: str                 # the status line, "timeout" or why it failed


def exchange(port: int, request: bytes, timeout_s: float = TIMEOUT_S) -> Reply:
    """Sends `request` on a fresh connection and reads the whole response, all within
    timeout_s (an overall deadline, unlike http.client's per-operation timeout)."""
    start = time.monotonic()
    deadline = start + timeout_s
    data = b""
    try:
        with socket.create_connection((HOST, port), timeout=timeout_s) as sock:
            try:
                sock.sendall(request)
            except OSError:  # the server may have answered and closed early: read what it sent
                pass
            while True:
                head_end = data.find(b"\r\n\r\n")
                if head_end >= 0:
                    length = content_length(data[:head_end])
                    if length is not None and len(data) - head_end - 4 >= length:
                        break
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return Reply(None, "timeout")
                sock.settimeout(remaining)
                chunk = sock.recv(65536)
                if not chunk:  # closed: complete only for a head without Content-Length
                    if head_end >= 0 and content_length(data[:head_end]) is None:
                        break
                    return Reply(None, "closed without response" if not data else "closed mid-response")
                data += chunk
    except socket.timeout:
        return Reply(None, "timeout")
    except OSError as e:
        return Reply(None, f"{type(e).__name__}")
    return Reply(time.monotonic() - start, status_line(data))


def content_length(head: bytes) -> Optional[int]:
    values = [v for n, _, v in (line.partition(b":") for line in head.split(b"\r\n")[1:])
              if n.strip().lower() == b"content-length"]
    return int(values[0]) if values else None


def get(port: int, path: str, timeout_s: float = TIMEOUT_S) -> Reply:
    return exchange(port, f"GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".encode(), timeout_s)


def answered(reply: Reply) -> bool:
    return reply.latency_s is not None and reply.status.split(" ")[1:2] == ["200"]


class SlowClients:
    """N connections dripping a never-ending request head from one background thread, so
    N stay open: one the server closes is counted and replaced."""

    def __init__(self, port: int, count: int) -> None:
        self.port = port
        self.closed_by_server = 0
        self.open_failures = 0
        self._stop = threading.Event()
        self._sockets: List[Optional[socket.socket]] = [self._open() for _ in range(count)]
        self._thread = threading.Thread(target=self._drip, daemon=True)
        self._thread.start()

    def _open(self) -> Optional[socket.socket]:
        try:
            sock = socket.create_connection((HOST, self.port), timeout=2)
            sock.sendall(SLOW_PREFIX)
            sock.setblocking(False)
            return sock
        except OSError:
            self.open_failures += 1
            return None

    def _drip(self) -> None:
        while not self._stop.wait(1.0):
            for i, sock in enumerate(self._sockets):
                if sock is not None and self._still_open(sock):
                    continue
                if sock is not None:
                    sock.close()
                    self.closed_by_server += 1
                self._sockets[i] = self._open()

    @staticmethod
    def _still_open(sock: socket.socket) -> bool:
        try:
            if sock.recv(4096) == b"":  # EOF is a close; an answer (e.g. 408) is read and dropped
                return False
        except BlockingIOError:  # nothing from the server: as it should be
            pass
        except OSError:
            return False
        try:
            sock.send(b"a")
            return True
        except BlockingIOError:  # send buffer full: the server is not reading, but the connection is open
            return True
        except OSError:
            return False

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        for sock in self._sockets:
            if sock is not None:
                sock.close()


def post_large_body(port: int, body_bytes: int, limit_s: float = 30.0) -> Tuple[int, str]:
    """Body bytes the server's socket accepted, and the status line (or why there is none)."""
    deadline = time.monotonic() + limit_s
    received = b""
    sent = 0
    closed = False
    chunk = memoryview(b"x" * MIB)
    with socket.create_connection((HOST, port), timeout=TIMEOUT_S) as sock:
        sock.sendall(f"POST /metrics HTTP/1.1\r\nHost: x\r\nContent-Length: {body_bytes}\r\n\r\n".encode())
        sock.setblocking(False)
        while not closed and b"\r\n" not in received and time.monotonic() < deadline:
            writers = [sock] if sent < body_bytes else []
            readable, writable, _ = select.select([sock], writers, [], max(0.0, min(1.0, deadline - time.monotonic())))
            try:
                if readable:  # an early answer (413, 400) or a close ends the upload
                    data = sock.recv(65536)
                    closed = data == b""
                    received += data
                if writable and not closed:
                    offset = sent % MIB
                    sent += sock.send(chunk[offset:min(MIB, offset + body_bytes - sent)])
            except BlockingIOError:
                pass
            except OSError as e:
                return sent, f"{type(e).__name__} after {sent / MIB:.1f} MiB" + (
                    f", after response {status_line(received)}" if received else "")
    if b"\r\n" in received:
        return sent, status_line(received)
    return sent, "closed without response" if closed else f"no response in {limit_s:g} s"


def status_line(response: bytes) -> str:
    return response.split(b"\r\n", 1)[0].decode(errors="replace")


def memory_mib(pid: int) -> Tuple[float, float]:
    """VmRSS and VmHWM (peak RSS) of the process, in MiB."""
    with open(f"/proc/{pid}/status") as f:
        kib = {name: value.split()[0] for name, _, value in (line.partition(":") for line in f) if value.strip()}
    return int(kib["VmRSS"]) / 1024, int(kib["VmHWM"]) / 1024


def describe(replies: List[Reply]) -> Tuple[str, bool]:
    """'median/max ms, timeouts' of a batch of probes, and whether all answered within TARGET_MS.
    A probe without an answer counts as infinitely slow, so a median is only finite when
    most answered."""
    latencies = sorted(r.latency_s * 1000 if answered(r) and r.latency_s is not None else float("inf")
                       for r in replies)
    timeouts = sum(r.status == "timeout" for r in replies)
    others = [r.status for r in replies if not answered(r) and r.status != "timeout"]

    def ms(v: float) -> str:
        return f"{v:.1f}" if v != float("inf") else f">{TIMEOUT_S * 1000:.0f}"
    text = (f"median {ms(statistics.median(latencies))} ms, max {ms(latencies[-1])} ms, "
            f"{timeouts}/{len(replies)} timeouts" + (f", failed: {', '.join(sorted(set(others)))}" if others else ""))
    return text, latencies[-1] <= TARGET_MS


def still_answers(port: int, after: str) -> Tuple[str, str, str, str]:
    reply = get(port, "/healthz")
    return f"GET /healthz after {after}", describe([reply])[0], "answers", "meets" if answered(reply) else "MISSES"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--server", required=True, help="path to nupmpc-server")
    parser.add_argument("--slow", default="8,64,300", help="numbers of slow connections, one phase each")
    parser.add_argument("--body_mib", type=int, default=256)
    args = parser.parse_args()
    slow_counts = [int(c) for c in args.slow.split(",")]

    # 300 slow connections plus probes; the server inherits the raised limit.
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))

    port = free_port()
    server = subprocess.Popen([args.server, f"--address={HOST}:0", f"--metrics_address={HOST}:{port}",
                               "--log_level=warn"])
    rows: List[Tuple[str, str, str, str]] = []  # measurement, result, target, verdict
    try:
        deadline = time.monotonic() + 30
        while not answered(get(port, "/healthz", 1.0)):
            if server.poll() is not None or time.monotonic() > deadline:
                sys.exit(f"the server did not answer /healthz on port {port} within 30 s")
            time.sleep(0.1)

        baseline = [get(port, "/healthz") for _ in range(20)]
        rows.append(("baseline: 20 sequential GET /healthz", describe(baseline)[0], "", ""))

        for count in slow_counts:
            print(f"slow phase: {count} connections", file=sys.stderr)
            slow = SlowClients(port, count)
            time.sleep(2.0)  # let the drip settle in before probing
            probes = {"/healthz": 10, "/metrics": 5}
            replies: Dict[str, List[Reply]] = {path: [] for path in probes}
            for path, n in probes.items():
                for _ in range(n):
                    replies[path].append(get(port, path))
                    time.sleep(0.5)
            slow.stop()
            for path in probes:  # the target is set at TARGET_SLOW; other counts are shown against it too
                text, ok = describe(replies[path])
                aside = "" if count == TARGET_SLOW else f" (target is at {TARGET_SLOW}; for information)"
                rows.append((f"{count} slow connections: GET {path}", text, f"all within {TARGET_MS:.0f} ms",
                             ("meets" if ok else "MISSES") + aside))
            rows.append((f"{count} slow connections: closed by server", f"{slow.closed_by_server}"
                         + (f" ({slow.open_failures} reopen/open failures)" if slow.open_failures else ""), "", ""))
            time.sleep(1.0)  # the server drains the probes it queued behind the slow connections

        print(f"large body: {args.body_mib} MiB", file=sys.stderr)
        rss_before, peak_before = memory_mib(server.pid)
        sent, status = post_large_body(port, args.body_mib * MIB)
        time.sleep(1.0)
        rss_after, peak = memory_mib(server.pid)
        rows.append((f"POST /metrics with a {args.body_mib} MiB body",
                     f"{sent / MIB:.1f} MiB accepted by send; response: {status}", "", ""))
        growth = peak - peak_before
        rows.append(("server RSS before / after / peak (VmHWM) of the body",
                     f"{rss_before:.1f} / {rss_after:.1f} / {peak:.1f} MiB (peak grew {growth:+.1f} MiB "
                     f"from {peak_before:.1f} MiB)",
                     f"peak grows at most {TARGET_RSS_MIB:.0f} MiB", "meets" if growth <= TARGET_RSS_MIB
                     else "MISSES"))
        rows.append(still_answers(port, "the body"))

        print("10,000 header lines", file=sys.stderr)
        headers = "".join(f"X-h{i}: v\r\n" for i in range(10000))
        reply = exchange(port, f"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n{headers}\r\n".encode())
        rows.append(("GET /healthz with 10,000 header lines",
                     f"response: {reply.status}" + (f" in {reply.latency_s * 1000:.1f} ms" if reply.latency_s else ""),
                     "", ""))
        rows.append(still_answers(port, "the headers"))
    finally:
        started = time.monotonic()
        server.send_signal(signal.SIGTERM)
        try:
            code = server.wait(timeout=15)
            stop_note = f"SIGTERM: the server exited with {code} after {time.monotonic() - started:.1f} s"
        except subprocess.TimeoutExpired:
            server.kill()
            stop_note = f"SIGTERM: the server had not exited after 15 s and was killed (SIGKILL: {server.wait()})"

    print(f"metrics port probe of {args.server} ({os.cpu_count()} CPUs, probe timeout {TIMEOUT_S:g} s, "
          f"RLIMIT_NOFILE {hard}, was {soft})")
    print("\n| measurement | result | target | verdict |\n| --- | --- | --- | --- |")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(f"\n{stop_note}")


if __name__ == "__main__":
    main()
