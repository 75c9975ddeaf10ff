"""Fixtures: a real nupmpc-server binary on a free loopback port (no mocks), started by
nupmpc.local_server.

Paths come from the environment ctest sets (NUPMPC_SERVER_BINARY, NUPMPC_CLI_BINARY,
NUPMPC_BENCHMARK_DIR), else the default build tree next to this checkout. A missing binary
is an error, never a skip."""

import os
import pathlib
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO / "client" / "python"))
sys.path.insert(0, os.environ.get("NUPMPC_PYTHON_STUBS", str(REPO / "build" / "python")))

import nupmpc  # noqa: E402
from nupmpc.local_server import LocalServer, LocalServerError, default_binary  # noqa: E402

SERVER_BINARY = default_binary()
CLI_BINARY = os.environ.get("NUPMPC_CLI_BINARY", str(REPO / "build" / "bin" / "nupmpc"))
BENCHMARKS = pathlib.Path(os.environ.get("NUPMPC_BENCHMARK_DIR", str(REPO / "benchmarks")))


class ServerProcess(LocalServer):
    """The suite's server: started at once with 2 workers; restart() and start() after
    kill() bring a new process up on the same port; a server that does not start fails
    the test."""

    def __init__(self, *flags, port=None):
        super().__init__(SERVER_BINARY, "--threads", "2", *flags, port=port)
        try:
            self.start()
        except BaseException:  # pytest.fail's exception too: the log goes with it
            self.stop()
            raise

    def start(self, timeout_s=20.0):
        try:
            return super().start(timeout_s)
        except LocalServerError as error:
            pytest.fail(str(error), pytrace=False)


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
