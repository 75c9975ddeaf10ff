"""A session on a Control stream (the main path), riding through server restarts.

When its stream breaks (UNAVAILABLE, a cancellation it did not make, a stream that ended
without a status or without an error) a step re-creates the session from the spec it holds
(kept current with every answered step, nupmpc.spec_update) with back-off
(nupmpc.reconnect) and resends itself, so step() returns that step's plan; only a spent
budget makes it raise Unavailable. The semantics of the C++ client (client/client.cc).
"""

import queue
import threading
import time

import grpc

from nupmpc._proto import pb, pb_grpc
from nupmpc.errors import NupmpcError, Unavailable, error_from_code, error_from_rpc
from nupmpc.reconnect import ReconnectOptions, ReconnectStats, is_retryable, ride_out_outage
from nupmpc.result import Plan
from nupmpc.spec_update import apply_step_to_spec
from nupmpc.step import build_step, dims_of

_END = object()


def broken_stream_error(error, what):
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


class _Stream:
    """One Control call: requests through a queue, responses read one at a time."""

    def __init__(self, stub):
        self._requests = queue.Queue()
        self.call = stub.Control(iter(self._requests.get, _END))

    def send(self, request):
        self._requests.put(request)

    def receive(self, what):
        try:
            return next(self.call)
        except StopIteration:
            raise broken_stream_error(None, what) from None
        except grpc.RpcError as error:
            raise broken_stream_error(error, what) from None

    def close(self):
        """Half-closes and waits for the server to end the call."""
        self._requests.put(_END)
        try:
            for _ in self.call:
                pass
        except grpc.RpcError:
            pass

    def cancel(self):
        self._requests.put(_END)
        self.call.cancel()


class Session:
    """session.step(x, ...) → Plan, one control period; see step() for the arguments."""

    def __init__(self, client, spec, reconnect=None):
        self._client = client
        self._spec = spec
        self._dims = dims_of(spec)
        self._options = reconnect or ReconnectOptions()
        self._lock = threading.Lock()
        self._channel = client._channel
        self._own_channel = False
        self._stream = None
        self._sequence = 1
        self.id = None
        self.stats = ReconnectStats()
        with self._lock:
            self._connect(self._options.attempt_timeout_s)

    @property
    def spec(self):
        """The spec the session would be re-created from (kept current with every step)."""
        copy = pb.ProblemSpec()
        copy.CopyFrom(self._spec)
        return copy

    @property
    def dims(self):
        """(M, L, K, N)."""
        return self._dims

    @property
    def reconnects(self):
        return self.stats.reconnects

    def _connect(self, timeout_s):
        """Opens a stream that creates the session; cancelled after `timeout_s`."""
        stream = _Stream(pb_grpc.MpcServiceStub(self._channel))
        fired = threading.Event()

        def expire():
            fired.set()
            stream.cancel()

        timer = threading.Timer(timeout_s, expire)
        timer.start()
        try:
            stream.send(pb.ControlRequest(spec=self._spec, sequence=self._next_sequence()))
            response = stream.receive("attach")
        except NupmpcError:
            if fired.is_set():
                raise Unavailable(f"no session within the attempt timeout of {timeout_s * 1000:.0f} ms") from None
            stream.cancel()
            raise
        finally:
            timer.cancel()
        if response.error_code != 0:
            stream.cancel()
            raise error_from_code(response.error_code, response.error_message)
        self._stream = stream
        self.id = response.session_id

    def _next_sequence(self):
        sequence = self._sequence
        self._sequence += 1
        return sequence

    def _tear_down(self):
        if self._stream is not None:
            self._stream.cancel()
            self._stream = None

    def _step_once(self, step):
        if self._stream is None:
            raise Unavailable("not connected")
        sequence = self._next_sequence()
        self._stream.send(pb.ControlRequest(sequence=sequence, step=step))
        while True:
            try:
                response = self._stream.receive("read")
            except NupmpcError as error:
                if is_retryable(error):
                    self._tear_down()
                raise
            if response.sequence != sequence:
                continue  # an older step superseded by this one
            if response.error_code != 0:
                raise error_from_code(response.error_code, response.error_message)
            return response.result

    def _recreate_and_resend(self, step):
        def attempt(timeout_s):
            # A channel whose connection attempts were refused while the server was down
            # keeps failing calls at once until its own back-off (1 s growing ×1.6) lets it
            # retry: every attempt gets a new channel with a connection of its own.
            if self._own_channel:
                self._channel.close()
            self._channel = self._client.new_channel(own_subchannel=True)
            self._own_channel = True
            self._connect(timeout_s)
            return self._step_once(step)
        return attempt

    def step(self, x=None, references=None, bounds=None, input_references=None, input_bounds=None, shift=False,
             warm_start=None, max_iterations=0, time_limit_ms=0.0, previous_input=None, model=None):
        """Solves one period for the measured state `x` (M,) and returns its Plan.

        references: output references, (K,) or (N+1, K) (GP sessions: r, 1 or N values);
        bounds: (lower, upper) of the outputs, each (K,) or (N+1, K), None for a side kept;
        input_references, input_bounds: the same for the inputs ((L,) or (N, L));
        shift: move every stored per-step prior one step first (receding references);
        warm_start: None/"shift", "keep" or "cold"; previous_input: u[-1] (Δu problems);
        model: new model terms for this period (a nupmpc.ModelUpdate; a pb.ModelUpdate is
        sent unchecked), kept for later steps as the prior updates are.
        Raises ShapeError (before sending) or a typed NupmpcError from the server."""
        step = build_step(self._spec, x, references, bounds, input_references, input_bounds, shift, warm_start,
                          max_iterations, time_limit_ms, previous_input, model)
        with self._lock:
            start = time.perf_counter()
            try:
                result = self._step_once(step)
            except NupmpcError as error:
                if not is_retryable(error):
                    raise
                self._tear_down()
                result = ride_out_outage(self._options, error, self._recreate_and_resend(step), self.stats)
            round_trip_ms = (time.perf_counter() - start) * 1e3
            apply_step_to_spec(step, result, self._spec)
        return Plan(result, self._dims, round_trip_ms)

    def close(self):
        """Ends the stream (the server closes the session)."""
        with self._lock:
            if self._stream is not None:
                self._stream.close()
                self._stream = None
            if self._own_channel:
                self._channel.close()
                self._own_channel = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
