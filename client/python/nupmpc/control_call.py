"""One Control call of a session (the Python side of client/control_call.h): requests go
out through a one-slot iterator that gRPC's own thread drains, so a stalled network never
blocks a step and a newer request replaces one still waiting (the server's "newest state
wins"); responses are read by a thread of the call's own into an inbox, so a step can stop
waiting at its deadline."""

from __future__ import annotations

import queue
import threading
import time
from typing import Optional, Union

import grpc

from nupmpc._proto import pb, pb_grpc
from nupmpc.errors import CallStatus, NupmpcError, Unavailable, error_from_code, error_from_rpc

_END = object()
# The header a balancer routes calls addressed by a session id by (client/session_routing.h).
SESSION_HEADER = "x-nupmpc-session"
# What the reader thread puts in the inbox: a response, or (_END, the call's error or None).
_Item = Union[pb.ControlResponse, tuple[object, Optional[grpc.RpcError]]]


def broken_stream_error(error: CallStatus | None, what: str) -> NupmpcError:
    """The error of a stream that broke: retryable (Unavailable) when the server or the
    connection went away, else the server's typed error."""
    if error is None:
        return Unavailable(f"the Control stream ended ({what})")
    code = error.code()
    # This session never cancels a live stream: CANCELLED is the server dropping the call.
    # UNKNOWN is gRPC's word for a stream that ended without a status (a balancer whose
    # replica died). Both are as retryable as a lost connection.
    if code in (grpc.StatusCode.CANCELLED, grpc.StatusCode.UNKNOWN):
        return Unavailable(f"the Control stream broke ({what}): {code.name}: {error.details()}")
    typed = error_from_rpc(error)
    return typed


class _NewestRequest:
    """The request iterator of a Control call: gRPC's thread takes the next request when
    it can write, and a request put while the previous one still waits replaces it (the
    network stalls): the replaced one never reaches the server, as the server's own "newest
    state wins" would have treated it, and its report of held periods goes with the new one."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._waiting: pb.ControlRequest | None = None
        self._ended = False

    def put(self, request: pb.ControlRequest) -> int | None:
        """Queues `request`; returns the sequence of the request it replaced, if any."""
        with self._cond:
            dropped = self._waiting
            if dropped is not None:
                request.held_periods += dropped.held_periods
            self._waiting = request
            self._cond.notify()
        return None if dropped is None else dropped.sequence

    def end(self) -> None:
        with self._cond:
            self._ended = True
            self._cond.notify()

    def __iter__(self) -> _NewestRequest:
        return self

    def __next__(self) -> pb.ControlRequest:
        with self._cond:
            self._cond.wait_for(lambda: self._waiting is not None or self._ended)
            if self._waiting is None:
                raise StopIteration
            request, self._waiting = self._waiting, None
            return request


class _Stream:
    """One Control call: requests through a one-slot iterator (gRPC's thread writes them,
    so a stalled network never blocks a step), responses read by a thread of its own into
    an inbox, so that a step can stop waiting at its deadline."""

    def __init__(self, channel: grpc.Channel, session_id: str | None = None) -> None:
        self._requests = _NewestRequest()
        self._inbox: queue.Queue[_Item] = queue.Queue()
        self.ended = False
        # A stream attaching by id carries the id in the routing header, so a balancer sends
        # it where the id's other calls go: the replica holding (or restoring) the session.
        metadata = ((SESSION_HEADER, session_id),) if session_id else None
        self.call = pb_grpc.MpcServiceStub(channel).Control(self._requests, metadata=metadata)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        error = None
        try:
            for response in self.call:
                self._inbox.put(response)
        except grpc.RpcError as e:
            error = e
        self.ended = True
        self._inbox.put((_END, error))

    def send(self, request: pb.ControlRequest) -> int | None:
        """Sends `request`; returns the sequence of an unsent one it replaced, if any."""
        return self._requests.put(request)

    def receive(self, what: str, deadline: float | None = None) -> pb.ControlResponse | None:
        """The next response; None once `deadline` (time.monotonic) has passed; raises the
        stream's error once it ended."""
        timeout = None if deadline is None else max(deadline - time.monotonic(), 0.0)
        try:
            item = self._inbox.get(timeout=timeout)
        except queue.Empty:
            return None
        if isinstance(item, tuple):  # (_END, error): responses are messages
            self._inbox.put(item)  # every later receive sees the end too
            raise broken_stream_error(item[1], what)
        return item

    def close(self, timeout_s: float | None = None) -> None:
        """Half-closes and waits (at most timeout_s) for the server to end the call."""
        self._requests.end()
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        try:
            while self.receive("close", deadline) is not None:
                pass
        except NupmpcError:
            return
        self.call.cancel()

    def cancel(self) -> None:
        self._requests.end()
        self.call.cancel()


def attach(channel: grpc.Channel, spec: pb.ProblemSpec, sequence: int, timeout_s: float,
           session_id: str | None = None) -> tuple[_Stream, str]:
    """A stream on `channel` attached to the session `session_id` when given, else to one
    it created from `spec`, and the session's id; cancelled and Unavailable when the server
    has not answered within timeout_s."""
    stream = _Stream(channel, session_id)
    hello = pb.ControlRequest(session_id=session_id, sequence=sequence) if session_id else \
        pb.ControlRequest(spec=spec, sequence=sequence)
    stream.send(hello)
    try:
        response = stream.receive("attach", time.monotonic() + timeout_s)
    except NupmpcError:
        stream.cancel()
        raise
    if response is None:
        stream.cancel()
        raise Unavailable(f"no session within the attempt timeout of {timeout_s * 1000:.0f} ms")
    if response.error_code != 0:
        stream.cancel()
        raise error_from_code(response.error_code, response.error_message)
    return stream, response.session_id or session_id or ""
