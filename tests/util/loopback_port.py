"""Loopback ports for the server processes the Python tests and scripts start (and restart).

The rule (below the kernel's ephemeral range, never port 0) is the Python package's
(client/python/nupmpc/local_server.py, free_loopback_ports), loaded from its file alone so
that this works on a bare interpreter, without the package's dependencies;
tests/util/loopback_port.cc follows it for the C++ tests.

    python3 tests/util/loopback_port.py [COUNT]   prints COUNT distinct ports (1)
"""

import importlib.util
import pathlib
import sys

_SOURCE = pathlib.Path(__file__).resolve().parents[2] / "client" / "python" / "nupmpc" / "local_server.py"
_spec = importlib.util.spec_from_file_location("_nupmpc_local_server", _SOURCE)
_local_server = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_local_server)


def free_ports(count=1):
    """`count` distinct loopback ports that bind now."""
    return _local_server.free_loopback_ports(count)


def free_port():
    return free_ports(1)[0]


if __name__ == "__main__":
    print(*free_ports(int(sys.argv[1]) if len(sys.argv) > 1 else 1))
