#!/usr/bin/env python3
"""Prints the servers of one HAProxy backend as seen on its stats socket.

    deploy/haproxy/haproxy-stat.py SOCKET [BACKEND]     (default backend: streams)

One line per server: name, status (UP, DOWN, ...), current and total sessions, and the
last health check's result (e.g. L7OK, L7RSP: an answer other than SERVING, L4CON: no
connection). For the
HTTP/2 backends of deploy/haproxy/haproxy-config.sh a session is one gRPC call: a Control
stream or a unary call). Used by deploy/scaleout-test.sh to show how calls spread.
"""
import csv
import io
import socket
import sys


def show_stat(path):
    with socket.socket(socket.AF_UNIX) as s:
        s.connect(path)
        s.sendall(b"show stat\n")
        chunks = []
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            chunks.append(chunk)
    text = b"".join(chunks).decode().lstrip("# ")
    return list(csv.DictReader(io.StringIO(text)))


def main():
    if len(sys.argv) not in (2, 3):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    backend = sys.argv[2] if len(sys.argv) == 3 else "streams"
    for row in show_stat(sys.argv[1]):
        if row["pxname"] == backend and row["svname"] not in ("FRONTEND", "BACKEND"):
            print(row["svname"], row["status"].split(" ")[0], row["scur"], row["stot"], row["check_status"] or "-")
    return 0


if __name__ == "__main__":
    sys.exit(main())
