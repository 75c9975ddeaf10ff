"""Loopback ports for the server processes the Python tests and scripts start (and restart).

Drawn at random from below the kernel's ephemeral range (or above it where nothing is
below), not bound to port 0: the kernel picks the source port of every outgoing
connection from that range, so a port it handed out could be taken by a connection of a
test running beside this one before the server binds it, or while the server is down for
a restart. tests/util/loopback_port.cc does the same for the C++ tests, and
client/python/nupmpc/local_server.py (free_loopback_ports) for the Python package's
server launcher, which the package cannot import from here.

    python3 tests/util/loopback_port.py [COUNT]   prints COUNT distinct ports (1)
"""

import random
import socket
import sys

LOWEST_PORT = 10000  # ports under this are left to services
LEAST_PORTS = 1000   # a narrower range below the ephemeral ports: use the one above


def _ephemeral_range():
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            first, last = (int(v) for v in f.read().split())
        if first <= last:
            return first, last
    except (OSError, ValueError):
        pass
    return 32768, 60999  # Linux's default


def free_ports(count=1):
    """`count` distinct loopback ports that bind now (without SO_REUSEADDR, so ports with
    connections in TIME_WAIT are passed over)."""
    first, last = _ephemeral_range()
    usable = range(LOWEST_PORT, first) if first - LOWEST_PORT >= LEAST_PORTS else range(last + 1, 65536)
    held = []  # held while drawing, so the ports are distinct
    try:
        for _ in range(1000):
            s = socket.socket()
            try:
                s.bind(("127.0.0.1", random.choice(usable)))
            except OSError:
                s.close()
                continue
            held.append(s)
            if len(held) == count:
                return [h.getsockname()[1] for h in held]
    finally:
        for h in held:
            h.close()
    raise RuntimeError(f"no {count} free loopback ports in {usable.start}-{usable.stop - 1}")


def free_port():
    return free_ports(1)[0]


if __name__ == "__main__":
    print(*free_ports(int(sys.argv[1]) if len(sys.argv) > 1 else 1))
