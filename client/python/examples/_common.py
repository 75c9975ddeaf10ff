"""What the examples share: where the server is (--server, or a nupmpc-server binary
started here by nupmpc.local_server on a free loopback port and stopped at the end), where
figures go (--out, default a temporary folder), and the import path of a checkout
(build/python with the generated stubs, client/python with the package)."""

import argparse
import atexit
import os
import pathlib
import sys
import tempfile

REPO = pathlib.Path(__file__).resolve().parents[3]
for path in (REPO / "client" / "python", REPO / "build" / "python"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from nupmpc.local_server import LocalServer, LocalServerError, ServerBinaryMissing, default_binary  # noqa: E402

BENCHMARKS = pathlib.Path(os.environ.get("NUPMPC_BENCHMARK_DIR", REPO / "benchmarks"))


def arguments(description, **extra):
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--server", default=os.environ.get("NUPMPC_SERVER"),
                        help="HOST:PORT of a running nupmpc-server (default: start --server_binary here)")
    parser.add_argument("--server_binary", default=default_binary(),
                        help="the nupmpc-server to start (default: $NUPMPC_SERVER_BINARY, else build/bin's)")
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
    """nupmpc-server on a free loopback port, stopped when the example exits: its target."""
    server = LocalServer(binary)
    try:
        server.start()
    except ServerBinaryMissing as error:
        server.stop()
        sys.exit(f"{error}, or pass --server HOST:PORT")
    except LocalServerError as error:
        server.stop()
        sys.exit(f"nupmpc-server did not start: {error}")
    atexit.register(server.stop)
    return server.target
