"""The asyncio variant: the same client and session on grpc.aio.

    async with nupmpc.aio.connect("127.0.0.1:50051") as client:
        session = await client.session(problem)
        plan = await session.step(x)

Sessions re-create themselves after a server restart exactly as nupmpc.Session does (the
same reconnect options, spec bookkeeping and step building)."""

import asyncio
import time

import grpc
import grpc.aio

from nupmpc._proto import pb, pb_grpc
from nupmpc.client import _Connection, spec_of
from nupmpc.errors import NupmpcError, Unavailable, error_from_code, error_from_rpc
from nupmpc.reconnect import ReconnectOptions, ReconnectStats, is_retryable, ride_out_outage_async
from nupmpc.result import Plan
from nupmpc.control_call import broken_stream_error
from nupmpc.spec_update import apply_step_to_spec
from nupmpc.step import build_step, dims_of


class AsyncClient(_Connection):
    _insecure_channel = staticmethod(grpc.aio.insecure_channel)
    _secure_channel = staticmethod(grpc.aio.secure_channel)

    async def _call(self, method, request):
        try:
            return await method(request, timeout=self.deadline_s)
        except grpc.RpcError as error:
            raise error_from_rpc(error) from None

    async def solve_once(self, problem):
        spec = spec_of(problem)
        start = time.perf_counter()
        response = await self._call(self._stub.SolveOnce, pb.SolveOnceRequest(spec=spec))
        return Plan(response.result, dims_of(spec), (time.perf_counter() - start) * 1e3)

    async def server_info(self):
        return await self._call(self._stub.GetServerInfo, pb.GetServerInfoRequest())

    async def session(self, problem, reconnect=None):
        session = AsyncSession(self, spec_of(problem), reconnect)
        async with session._lock:
            await session._connect(session._options.attempt_timeout_s)
        self._sessions.add(session)
        return session

    async def close(self):
        for session in list(self._sessions):
            await session.close()
        self._sessions.clear()
        await self._channel.close()

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc):
        await self.close()


def connect(target, **security):
    """An AsyncClient (use with `async with`); the arguments of nupmpc.connect."""
    return AsyncClient(target, **security)


class AsyncSession:
    def __init__(self, client, spec, reconnect=None):
        self._client = client
        self._spec = spec
        self._dims = dims_of(spec)
        self._options = reconnect or ReconnectOptions()
        self._lock = asyncio.Lock()
        self._channel = client._channel
        self._own_channel = False
        self._call = None
        self._sequence = 1
        self.id = None
        self.stats = ReconnectStats()

    spec = property(lambda self: pb.ProblemSpec.FromString(self._spec.SerializeToString()))
    dims = property(lambda self: self._dims)
    reconnects = property(lambda self: self.stats.reconnects)

    def _next_sequence(self):
        sequence = self._sequence
        self._sequence += 1
        return sequence

    async def _exchange(self, call, request, what):
        """Writes `request` (None: nothing) and reads the next response; typed errors."""
        try:
            if request is not None:
                await call.write(request)
            response = await call.read()
        except grpc.RpcError as error:
            raise broken_stream_error(error, what) from None
        except asyncio.InvalidStateError:
            raise Unavailable(f"the Control stream ended ({what})") from None
        if response is grpc.aio.EOF:
            code = await call.code()
            if code != grpc.StatusCode.OK:
                raise broken_stream_error(_Finished(code, await call.details()), what)
            raise broken_stream_error(None, what)
        return response

    async def _connect(self, timeout_s):
        call = pb_grpc.MpcServiceStub(self._channel).Control()
        hello = pb.ControlRequest(spec=self._spec, sequence=self._next_sequence())
        try:
            response = await asyncio.wait_for(self._exchange(call, hello, "attach"), timeout_s)
        except asyncio.TimeoutError:
            call.cancel()
            raise Unavailable(f"no session within the attempt timeout of {timeout_s * 1000:.0f} ms") from None
        except NupmpcError:
            call.cancel()
            raise
        if response.error_code != 0:
            call.cancel()
            raise error_from_code(response.error_code, response.error_message)
        self._call = call
        self.id = response.session_id

    def _tear_down(self):
        if self._call is not None:
            self._call.cancel()
            self._call = None

    async def _step_once(self, step):
        if self._call is None:
            raise Unavailable("not connected")
        sequence = self._next_sequence()
        request = pb.ControlRequest(sequence=sequence, step=step)
        while True:
            try:
                response = await self._exchange(self._call, request, "read")
            except NupmpcError as error:
                if is_retryable(error):
                    self._tear_down()
                raise
            request = None
            if response.sequence != sequence:
                continue  # an older step superseded by this one
            if response.error_code != 0:
                raise error_from_code(response.error_code, response.error_message)
            return response.result

    async def step(self, x=None, references=None, bounds=None, input_references=None, input_bounds=None,
                   shift=False, warm_start=None, max_iterations=0, time_limit_ms=0.0, previous_input=None, model=None):
        """nupmpc.Session.step, awaited."""
        step = build_step(self._spec, x, references, bounds, input_references, input_bounds, shift, warm_start,
                          max_iterations, time_limit_ms, previous_input, model)
        async with self._lock:
            start = time.perf_counter()
            try:
                result = await self._step_once(step)
            except NupmpcError as error:
                if not is_retryable(error):
                    raise
                self._tear_down()

                async def attempt(timeout_s):
                    if self._own_channel:
                        await self._channel.close()
                    self._channel = self._client.new_channel(own_subchannel=True)
                    self._own_channel = True
                    await self._connect(timeout_s)
                    return await self._step_once(step)

                result = await ride_out_outage_async(self._options, error, attempt, self.stats)
            round_trip_ms = (time.perf_counter() - start) * 1e3
            apply_step_to_spec(step, result, self._spec)
        return Plan(result, self._dims, round_trip_ms)

    async def close(self):
        async with self._lock:
            if self._call is not None:
                try:
                    await self._call.done_writing()
                    while await self._call.read() is not grpc.aio.EOF:
                        pass
                except (grpc.RpcError, asyncio.InvalidStateError):
                    pass
                self._call = None
            if self._own_channel:
                await self._channel.close()
                self._own_channel = False


class _Finished(grpc.RpcError):
    """A finished call's status in the shape broken_stream_error reads."""

    def __init__(self, code, details):
        self._code, self._details = code, details

    def code(self):
        return self._code

    def details(self):
        return self._details
