"""Run a local nupmpc-server for examples and tests: the binary as a child process on a
loopback port, its output in a log file, stopped, killed or restarted on the same port.

    from nupmpc.local_server import LocalServer

    with LocalServer() as server:                       # the binary of default_binary()
        with nupmpc.connect(server.target) as client:
            ...

    server = LocalServer(None, "--threads", "2").start()
    server.kill()                                       # SIGKILL, as in a crash
    server.start()                                      # a new process on the same port
    code = server.terminate(timeout_s=30)               # SIGTERM: the exit code
    server.stop()                                       # ends it if running, deletes the log

The port is drawn at random from below the kernel's ephemeral range (or above it where
nothing is below), never bound to port 0: the kernel picks the source port of every
outgoing connection from that range, so a port it handed out could be taken by another
process's connection before the server binds it, or while the server is down for a
restart. tests/util/loopback_port.py loads this rule from here; tests/util/loopback_port.cc
follows it for the C++ tests.

Ready means answering: grpc.health.v1 reports SERVING (the service needs no token, so
servers started with --auth_tokens_file are probed too), or, when the server was given a
metrics endpoint (metrics=True), its /readyz answers 200. A server with TLS
(--tls_cert_file) and no metrics endpoint cannot be probed without its client's
credentials: for it, ready means its port takes a TCP connection.
"""

from __future__ import annotations

import os
import pathlib
import random
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import urllib.request
from types import TracebackType
from typing import IO, TYPE_CHECKING, Iterable, Mapping

if TYPE_CHECKING:
    import grpc

__all__ = ["LocalServer", "LocalServerError", "ServerBinaryMissing", "default_binary", "free_loopback_ports",
           "BINARY_ENV"]

BINARY_ENV = "NUPMPC_SERVER_BINARY"  # where default_binary() looks first
HOST = "127.0.0.1"
LOWEST_PORT = 10000  # ports under this are left to services
LEAST_PORTS = 1000  # a narrower range below the ephemeral ports: use the one above
_HEALTH_CHECK = "/grpc.health.v1.Health/Check"
_SERVING = b"\x08\x01"  # HealthCheckResponse{status: SERVING}, serialized
# The readiness probe's channel retries a refused connection after 20 ms, not gRPC's
# default 1 s and more, and shares no connection with the clients of this process.
_PROBE_OPTIONS = [("grpc.initial_reconnect_backoff_ms", 20), ("grpc.min_reconnect_backoff_ms", 20),
                  ("grpc.max_reconnect_backoff_ms", 100), ("grpc.use_local_subchannel_pool", 1)]


class LocalServerError(RuntimeError):
    """The server could not be started, or did not become ready (the message ends with
    the tail of its log)."""


class ServerBinaryMissing(LocalServerError):
    """No executable nupmpc-server where it was looked for."""


def _checkout_binary() -> pathlib.Path:
    # client/python/nupmpc/local_server.py in a checkout: build/bin beside client/.
    return pathlib.Path(__file__).resolve().parents[3] / "build" / "bin" / "nupmpc-server"


def default_binary() -> str:
    """$NUPMPC_SERVER_BINARY; else build/bin/nupmpc-server of the checkout this package is
    in, if there is one; else nupmpc-server on PATH; else (missing) the checkout's path."""
    from_env = os.environ.get(BINARY_ENV)
    if from_env:
        return from_env
    checkout = _checkout_binary()
    if checkout.exists():
        return str(checkout)
    return shutil.which("nupmpc-server") or str(checkout)


def _ephemeral_range() -> tuple[int, int]:
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            first, last = (int(v) for v in f.read().split())
        if first <= last:
            return first, last
    except (OSError, ValueError):
        pass
    return 32768, 60999  # Linux's default


def free_loopback_ports(count: int = 1) -> list[int]:
    """`count` distinct loopback ports outside the ephemeral range that bind now (without
    SO_REUSEADDR, so ports with connections in TIME_WAIT are passed over)."""
    if count <= 0:
        return []
    first, last = _ephemeral_range()
    usable = range(LOWEST_PORT, first) if first - LOWEST_PORT >= LEAST_PORTS else range(last + 1, 65536)
    held: list[socket.socket] = []  # held while drawing, so that the ports are distinct
    try:
        for _ in range(1000):
            s = socket.socket()
            try:
                s.bind((HOST, random.choice(usable)))
            except OSError:
                s.close()
                continue
            held.append(s)
            if len(held) == count:
                return [h.getsockname()[1] for h in held]
    finally:
        for h in held:
            h.close()
    raise LocalServerError(f"no {count} free loopback ports in {usable.start}-{usable.stop - 1}")


class LocalServer:
    """nupmpc-server as a child process on 127.0.0.1.

    binary: the executable (None: default_binary()). flags: more command-line flags
    (--address, and --metrics_address with metrics=True, are the launcher's). port: the
    gRPC port (None: a free one, see free_loopback_ports); it stays the same across
    restarts. metrics: also serve /metrics, /healthz and /readyz on a port of their own
    (metrics_port), and take /readyz as readiness. cpus: the CPUs the server may run on
    (None: any). env: the server's environment (None: this process's). log_to_file: the
    server's stdout and stderr into a temporary file (log_text(), deleted by stop());
    False: discarded.

    Not started by the constructor: start(), or `with LocalServer(...) as server:`. Call
    stop() in the end, also after a start() that failed (it deletes the log).
    """

    def __init__(self, binary: str | os.PathLike[str] | None = None, *flags: str, port: int | None = None,
                 metrics: bool = False, cpus: Iterable[int] | None = None, env: Mapping[str, str] | None = None,
                 log_to_file: bool = True) -> None:
        self.binary = os.fspath(binary) if binary is not None else default_binary()
        self.flags: list[str] = list(flags)
        self.cpus: frozenset[int] | None = None if cpus is None else frozenset(cpus)
        self.env: dict[str, str] | None = None if env is None else dict(env)
        drawn = free_loopback_ports((port is None) + metrics)
        while port is not None and port in drawn:  # a given port is not held while drawing
            drawn = free_loopback_ports(len(drawn))
        self.port: int = port if port is not None else drawn.pop(0)
        self.metrics_port: int | None = drawn.pop(0) if metrics else None
        self.process: subprocess.Popen[bytes] | None = None  # the latest process, None before start()
        self.log_to_file = log_to_file
        self._log: IO[bytes] | None = None  # opened by the first start(), kept across restarts
        self._stopped = False

    # What the server is and where.

    @property
    def target(self) -> str:
        """HOST:PORT for nupmpc.connect and the command-line tools."""
        return f"{HOST}:{self.port}"

    @property
    def metrics_url(self) -> str:
        """http://HOST:PORT of the metrics endpoint (metrics=True only)."""
        if self.metrics_port is None:
            raise LocalServerError("this server has no metrics endpoint: construct it with metrics=True")
        return f"http://{HOST}:{self.metrics_port}"

    @property
    def pid(self) -> int:
        return self._started().pid

    @property
    def running(self) -> bool:
        """Started, and not exited (an exit is noticed here, not only by wait)."""
        return self.process is not None and self.process.poll() is None

    @property
    def log_path(self) -> str | None:
        """The log file (None before start(), with log_to_file=False, or after stop())."""
        return self._log.name if self._log is not None else None

    def command(self) -> list[str]:
        """The command line start() runs (without the CPU pinning)."""
        command = [self.binary, "--address", self.target]
        if self.metrics_port is not None:
            command += ["--metrics_address", f"{HOST}:{self.metrics_port}"]
        return command + self.flags

    def log_text(self, tail: int = 4000) -> str:
        """The last `tail` characters the server (all its processes, on restarts) wrote."""
        if self._log is None:
            return ""
        self._log.flush()
        with open(self._log.name, errors="replace") as f:
            return f.read()[-tail:]

    # Its life.

    def start(self, timeout_s: float = 20.0) -> LocalServer:
        """Starts a process on this server's port(s) and waits for it to be ready (see
        wait_ready). After kill() or terminate(): a new process, as a supervisor would."""
        if self._stopped:
            raise LocalServerError("start() after stop(): construct a new LocalServer")
        if self.running:
            raise LocalServerError(f"nupmpc-server already runs on {self.target} (pid {self.pid})")
        if not os.access(self.binary, os.X_OK):
            raise ServerBinaryMissing(f"no nupmpc-server at {self.binary}: build it (cmake --build build --target "
                                      f"nupmpc-server) or set {BINARY_ENV}")
        command = self.command()
        preexec = None
        if self.cpus is not None:
            # taskset execs the server (the pid stays), so no Python runs in the forked child.
            taskset = shutil.which("taskset")
            if taskset is not None:
                command = [taskset, "--cpu-list", ",".join(str(c) for c in sorted(self.cpus)), *command]
            else:
                cpus = self.cpus
                preexec = lambda: os.sched_setaffinity(0, cpus)  # noqa: E731
        if self.log_to_file and self._log is None:
            self._log = tempfile.NamedTemporaryFile(prefix="nupmpc-server-", suffix=".log", delete=False)
        output: IO[bytes] | int = self._log if self._log is not None else subprocess.DEVNULL
        try:
            self.process = subprocess.Popen(command, stdout=output, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                            env=self.env, preexec_fn=preexec)
        except OSError as error:  # e.g. the binary is being replaced by a build right now
            raise LocalServerError(f"could not run {self.binary}: {error}") from error
        try:
            self.wait_ready(timeout_s)
        except BaseException:
            self.kill()
            raise
        return self

    def wait_ready(self, timeout_s: float = 20.0) -> None:
        """Waits until the server answers (see the module's doc); LocalServerError with the
        log's tail if it exits first or is not ready within timeout_s."""
        process = self._started()
        deadline = time.monotonic() + timeout_s
        probe = self._probe()
        try:
            while True:
                if process.poll() is not None:
                    raise LocalServerError(f"nupmpc-server exited with {process.returncode} before it was ready:\n"
                                           f"{self.log_text()}")
                left = deadline - time.monotonic()
                if left <= 0:
                    raise LocalServerError(f"nupmpc-server not ready on {self.target} within {timeout_s:g} s:\n"
                                           f"{self.log_text()}")
                if probe.ready(min(left, 0.25)):
                    return
        finally:
            probe.close()

    def kill(self) -> None:
        """SIGKILL, and waits for the exit: no drain, no goodbye; streams break as in a crash."""
        if self.process is not None:
            self.process.kill()
            self.process.wait()

    def restart(self, timeout_s: float = 20.0) -> LocalServer:
        """kill(), then start() a new process on the same port(s)."""
        self.kill()
        return self.start(timeout_s)

    def terminate(self, timeout_s: float = 30.0) -> int | None:
        """SIGTERM (the server drains, then exits); the exit code, None if it did not exit
        within timeout_s (it is left running: stop() or kill() ends it)."""
        process = self._started()
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
        try:
            return process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def stop(self) -> None:
        """Ends the server if it runs (SIGTERM, SIGKILL after 10 s) and deletes its log.
        Idempotent; the server cannot be started again."""
        if self.running:
            if self.terminate(timeout_s=10) is None:
                self.kill()
        if self._log is not None:
            self._log.close()
            try:
                os.unlink(self._log.name)
            except FileNotFoundError:
                pass
            self._log = None
        self._stopped = True

    def __enter__(self) -> LocalServer:
        if self.process is None:
            try:
                self.start()
            except BaseException:
                self.stop()
                raise
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = "not started" if self.process is None else f"pid {self.process.pid}" + (
            "" if self.running else f", exited {self.process.returncode}")
        return f"LocalServer({self.target}, {state})"

    # Helpers.

    def _started(self) -> subprocess.Popen[bytes]:
        if self.process is None:
            raise LocalServerError("the server was not started: call start()")
        return self.process

    def _probe(self) -> _Probe:
        if self.metrics_port is not None:
            return _ReadyzProbe(f"{self.metrics_url}/readyz")
        if any(flag.startswith("--tls_cert_file") for flag in self.flags):
            return _TcpProbe(self.port)
        return _HealthProbe(self.target)


class _Probe:
    def ready(self, timeout_s: float) -> bool:
        """Within about timeout_s: whether the server is ready now."""
        raise NotImplementedError

    def close(self) -> None:
        pass


class _HealthProbe(_Probe):
    """grpc.health.v1.Health/Check for the whole server ("") on one plaintext channel."""

    def __init__(self, target: str) -> None:
        # Imported here, so that free_loopback_ports works without grpc (tests/util/loopback_port.py
        # loads this file on its own for scripts that run on a bare interpreter).
        import grpc

        self.channel = grpc.insecure_channel(target, options=_PROBE_OPTIONS)
        # Raw bytes both ways: the request is empty, the answer is SERVING or not.
        self.check = self.channel.unary_unary(_HEALTH_CHECK)

    def ready(self, timeout_s: float) -> bool:
        import grpc

        try:
            if self.check(b"", timeout=timeout_s, wait_for_ready=True) == _SERVING:
                return True
        except grpc.RpcError as error:
            if error.code() == grpc.StatusCode.DEADLINE_EXCEEDED:
                return False  # the time was spent waiting already
        time.sleep(0.02)  # NOT_SERVING, or refused at once
        return False

    def close(self) -> None:
        self.channel.close()


class _ReadyzProbe(_Probe):
    def __init__(self, url: str) -> None:
        self.url = url

    def ready(self, timeout_s: float) -> bool:
        try:
            with urllib.request.urlopen(self.url, timeout=timeout_s) as response:
                return bool(response.status == 200)
        except OSError:  # refused, timed out, or 503 (urllib's HTTPError is an OSError)
            time.sleep(0.02)
            return False


class _TcpProbe(_Probe):
    def __init__(self, port: int) -> None:
        self.port = port

    def ready(self, timeout_s: float) -> bool:
        try:
            with socket.create_connection((HOST, self.port), timeout=min(timeout_s, 0.2)):
                return True
        except OSError:
            time.sleep(0.02)
            return False
