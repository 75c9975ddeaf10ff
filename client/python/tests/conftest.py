"""Fixtures: a real nupmpc-server binary on a free loopback port (no mocks).

Paths come from the environment ctest sets (NUPMPC_SERVER_BINARY, NUPMPC_CLI_BINARY,
NUPMPC_BENCHMARK_DIR), else the default build tree next to this checkout. A missing binary
is an error, never a skip."""

import os
import pathlib
import socket
import subprocess
import sys
import tempfile
import time

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO / "client" / "python"))
sys.path.insert(0, os.environ.get("NUPMPC_PYTHON_STUBS", str(REPO / "build" / "python")))
sys.path.insert(0, str(REPO / "tests" / "util"))

import nupmpc  # noqa: E402
from loopback_port import free_port  # noqa: E402

SERVER_BINARY = os.environ.get("NUPMPC_SERVER_BINARY", str(REPO / "build" / "bin" / "nupmpc-server"))
CLI_BINARY = os.environ.get("NUPMPC_CLI_BINARY", str(REPO / "build" / "bin" / "nupmpc"))
BENCHMARKS = pathlib.Path(os.environ.get("NUPMPC_BENCHMARK_DIR", str(REPO / "benchmarks")))


class ServerProcess:
    """nupmpc-server as a child process; restart() starts a new one on the same port."""

    def __init__(self, *flags, port=None):
        if not os.access(SERVER_BINARY, os.X_OK):
            pytest.fail(f"no server binary at {SERVER_BINARY} (build nupmpc-server or set NUPMPC_SERVER_BINARY)")
        self.flags = list(flags)
        self.port = port or free_port()
        self.target = f"127.0.0.1:{self.port}"
        self.log = tempfile.NamedTemporaryFile(prefix="nupmpc-server-", suffix=".log", delete=False)
        self.process = None
        self.start()

    def start(self):
        self.process = subprocess.Popen([SERVER_BINARY, "--address", self.target, "--threads", "2", *self.flags],
                                        stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                pytest.fail(f"nupmpc-server exited with {self.process.returncode}:\n{self._log_text()}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.02)
        pytest.fail(f"nupmpc-server did not listen on {self.target} within 20 s:\n{self._log_text()}")

    def _log_text(self):
        self.log.flush()
        with open(self.log.name, errors="replace") as f:
            return f.read()[-4000:]

    def kill(self):
        """SIGKILL: no drain, no goodbye; streams break as in a crash."""
        self.process.kill()
        self.process.wait()

    def restart(self):
        self.kill()
        self.start()

    def stop(self):
        if self.process and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()
        os.unlink(self.log.name)


@pytest.fixture(scope="session")
def server():
    process = ServerProcess()
    yield process
    process.stop()


@pytest.fixture
def client(server):
    with nupmpc.connect(server.target) as c:
        yield c


@pytest.fixture(scope="session")
def masses():
    return nupmpc.load_instance(BENCHMARKS / "masses_N30.json")


@pytest.fixture(scope="session")
def reference():
    import json
    with open(BENCHMARKS / "reference.json") as f:
        return json.load(f)["instances"]


@pytest.fixture
def figure_dir(tmp_path):
    return tmp_path
