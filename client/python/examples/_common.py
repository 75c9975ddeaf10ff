"""What the examples share: where the server is (--server, or a nupmpc-server binary
started here on a free loopback port and stopped at the end), where figures go (--out,
default a temporary folder), and the import path of a checkout (build/python with the
generated stubs, client/python with the package)."""

import argparse
import atexit
import os
import pathlib
import socket
import subprocess
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parents[3]
for path in (REPO / "client" / "python", REPO / "build" / "python"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

BENCHMARKS = pathlib.Path(os.environ.get("NUPMPC_BENCHMARK_DIR", REPO / "benchmarks"))


def arguments(description, **extra):
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--server", default=os.environ.get("NUPMPC_SERVER"),
                        help="HOST:PORT of a running nupmpc-server (default: start --server_binary here)")
    parser.add_argument("--server_binary", default=os.environ.get("NUPMPC_SERVER_BINARY",
                                                                  str(REPO / "build" / "bin" / "nupmpc-server")))
    parser.add_argument("--out", default=None, help="folder for the figure (default: a new temporary folder)")
    for name, (default, text) in extra.items():
        parser.add_argument(f"--{name}", default=default, type=type(default), help=text)
    args = parser.parse_args()
    args.out = pathlib.Path(args.out or tempfile.mkdtemp(prefix="nupmpc-figures-"))
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.server:
        args.server = start_server(args.server_binary)
    return args


def start_server(binary):
    """nupmpc-server on a free loopback port, stopped when the example exits."""
    if not os.access(binary, os.X_OK):
        sys.exit(f"no nupmpc-server at {binary}: build it (cmake --build build --target nupmpc-server) "
                 "or pass --server HOST:PORT")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    process = subprocess.Popen([binary, "--address", f"127.0.0.1:{port}"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    atexit.register(lambda: (process.terminate(), process.wait()))
    for _ in range(500):
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return f"127.0.0.1:{port}"
        except OSError:
            time.sleep(0.02)
    sys.exit("nupmpc-server did not start")
