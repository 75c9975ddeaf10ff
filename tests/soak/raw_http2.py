"""Hand-written HTTP/2 for the misbehaving peers of faults.py (a gRPC library never sends
half a message): the connection preface, SETTINGS, the HEADERS of a Control call, and a
gRPC message prefix that promises more bytes than follow. Debian 12 has no Python h2."""

import socket
import struct
import time

PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"
DATA, HEADERS, SETTINGS = 0x0, 0x1, 0x4
END_HEADERS, ACK = 0x4, 0x1


def frame(kind, flags, stream, payload=b"", length=None):
    """One frame; `length` may claim more payload than is given (a partial frame)."""
    length = len(payload) if length is None else length
    return struct.pack(">I", length)[1:] + bytes([kind, flags]) + struct.pack(">I", stream) + payload


def _literal(name, value):
    """HPACK literal header field without indexing, new name, no Huffman (lengths < 127)."""
    name, value = name.encode(), value.encode()
    return b"\x00" + bytes([len(name)]) + name + bytes([len(value)]) + value


def control_call_headers(authority):
    return b"".join(_literal(n, v) for n, v in (
        (":method", "POST"), (":scheme", "http"), (":path", "/nupmpc.v1.MpcService/Control"),
        (":authority", authority), ("content-type", "application/grpc"), ("te", "trailers")))


def connect(port, handshake=True):
    """A TCP connection to the server; with `handshake`, the preface and SETTINGS are sent
    and the server's SETTINGS acknowledged, as any HTTP/2 client does."""
    s = socket.create_connection(("127.0.0.1", port), timeout=5)
    if handshake:
        s.sendall(PREFACE + frame(SETTINGS, 0, 0))
        s.settimeout(2)
        try:
            s.recv(65536)  # the server's SETTINGS (and perhaps its ACK of ours)
        except socket.timeout:
            pass
        s.sendall(frame(SETTINGS, ACK, 0))
    return s


def open_stream(s, stream_id, port):
    s.sendall(frame(HEADERS, END_HEADERS, stream_id, control_call_headers(f"127.0.0.1:{port}")))


def send_partial_message(s, stream_id, promised=1000, sent=10):
    """A DATA frame whose gRPC prefix promises `promised` bytes of which `sent` follow."""
    s.sendall(frame(DATA, 0, stream_id, b"\x00" + struct.pack(">I", promised) + b"\x0a" * sent))


def send_partial_frame(s, stream_id, promised=16000, sent=100):
    """A DATA frame header promising `promised` bytes of payload, of which `sent` follow:
    the start of a gRPC message as long as the frame (gRPC parses a frame's payload as it
    arrives, so the message must be incomplete too, or it would be handled at once)."""
    message = b"\x00" + struct.pack(">I", promised - 5) + b"\x0a" * (sent - 5)
    s.sendall(frame(DATA, 0, stream_id, message, length=promised))


def closed_by_peer(sockets, within_s):
    """Reads (and drops) what the server sends until each socket is closed by it or
    `within_s` passed; the number closed and the time the last one closed."""
    deadline = time.monotonic() + within_s
    open_ones = list(sockets)
    last = 0.0
    start = time.monotonic()
    for s in open_ones:
        s.setblocking(False)
    while open_ones and time.monotonic() < deadline:
        still = []
        for s in open_ones:
            try:
                data = s.recv(65536)
                if data:
                    still.append(s)
                else:
                    last = time.monotonic() - start
            except BlockingIOError:
                still.append(s)
            except OSError:  # reset: closed as well
                last = time.monotonic() - start
        open_ones = still
        if open_ones:
            time.sleep(0.05)
    return len(sockets) - len(open_ones), last
