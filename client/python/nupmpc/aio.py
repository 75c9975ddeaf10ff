"""The asyncio variant: the same client and session on grpc.aio.

    async with nupmpc.aio.connect("127.0.0.1:50051") as client:
        session = await client.session(problem)
        plan = await session.step(x)

Sessions re-create themselves after a server restart exactly as nupmpc.Session does (the
same reconnect options, spec bookkeeping and step building)."""

from __future__ import annotations

import asyncio
import time
import weakref
from types import TracebackType
from typing import Any, Awaitable, Callable, TypeVar

import grpc
import grpc.aio

from nupmpc._proto import pb, pb_grpc
from nupmpc.arrays import ArrayLike
from nupmpc.client import ProblemLike, _Connection, spec_of
from nupmpc.errors import NupmpcError, Unavailable, error_from_code, error_from_rpc
from nupmpc.reconnect import AttemptNote, ReconnectOptions, ReconnectStats, is_retryable, reattach_or_recreate_async, \
    ride_out_outage_async
from nupmpc.result import Plan
from nupmpc.control_call import SESSION_HEADER, broken_stream_error
from nupmpc.spec_update import apply_step_to_spec
from nupmpc.step import Bounds, Dims, StepModel, WarmStart, build_step, dims_of

_Reply = TypeVar("_Reply")


class AsyncClient(_Connection):
    _insecure_channel = staticmethod(grpc.aio.insecure_channel)
    _secure_channel = staticmethod(grpc.aio.secure_channel)

    _sessions: weakref.WeakSet[AsyncSession]

    async def _call(self, method: Callable[..., Awaitable[_Reply]], request: object) -> _Reply:
        try:
            return await method(request, timeout=self.deadline_s)
        except grpc.RpcError as error:
            raise error_from_rpc(error) from None

    async def solve_once(self, problem: ProblemLike) -> Plan:
        spec = spec_of(problem)
        start = time.perf_counter()
        response: pb.SolveOnceResponse = await self._call(self._stub.SolveOnce, pb.SolveOnceRequest(spec=spec))
        return Plan.from_result(response.result, dims_of(spec), (time.perf_counter() - start) * 1e3)

    async def server_info(self) -> pb.GetServerInfoResponse:
        info: pb.GetServerInfoResponse = await self._call(self._stub.GetServerInfo, pb.GetServerInfoRequest())
        return info

    async def session(self, problem: ProblemLike, reconnect: ReconnectOptions | None = None) -> AsyncSession:
        session = AsyncSession(self, spec_of(problem), reconnect)
        async with session._lock:
            await session._connect(session._options.attempt_timeout_s)
        self._sessions.add(session)
        return session

    async def close(self) -> None:
        for session in list(self._sessions):
            await session.close()
        self._sessions.clear()
        await self._channel.close()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, kind: type[BaseException] | None, value: BaseException | None,
                        traceback: TracebackType | None) -> None:
        await self.close()


def connect(target: str, **security: Any) -> AsyncClient:
    """An AsyncClient (use with `async with`); the arguments of nupmpc.connect."""
    return AsyncClient(target, **security)


class AsyncSession:
    def __init__(self, client: AsyncClient, spec: pb.ProblemSpec, reconnect: ReconnectOptions | None = None) -> None:
        self._client = client
        self._spec = spec
        self._dims = dims_of(spec)
        self._options = reconnect or ReconnectOptions()
        self._lock = asyncio.Lock()
        self._channel = client._channel
        self._own_channel = False
        self._call: grpc.aio.StreamStreamCall | None = None
        self._sequence = 1
        self.id: str | None = None
        self.stats = ReconnectStats()

    @property
    def spec(self) -> pb.ProblemSpec:
        copy = pb.ProblemSpec()
        copy.CopyFrom(self._spec)
        return copy

    @property
    def dims(self) -> Dims:
        return self._dims

    @property
    def reconnects(self) -> int:
        return self.stats.reconnects

    def _next_sequence(self) -> int:
        sequence = self._sequence
        self._sequence += 1
        return sequence

    async def _exchange(self, call: grpc.aio.StreamStreamCall, request: pb.ControlRequest | None,
                        what: str) -> pb.ControlResponse:
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
        reply: pb.ControlResponse = response
        return reply

    async def _connect(self, timeout_s: float, session_id: str | None = None) -> None:
        """A Control call attached to `session_id` (routed by it), or to a session it
        creates from the spec."""
        if session_id:
            call = pb_grpc.MpcServiceStub(self._channel).Control(metadata=((SESSION_HEADER, session_id),))
            hello = pb.ControlRequest(session_id=session_id, sequence=self._next_sequence())
        else:
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
        self.id = response.session_id or session_id

    def _tear_down(self) -> None:
        if self._call is not None:
            self._call.cancel()
            self._call = None

    async def _step_once(self, step: pb.Step) -> pb.SolveResult:
        if self._call is None:
            raise Unavailable("not connected")
        sequence = self._next_sequence()
        request: pb.ControlRequest | None = pb.ControlRequest(sequence=sequence, step=step)
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

    async def step(self, x: ArrayLike | None = None, *, references: ArrayLike | None = None,
                   bounds: Bounds | None = None, input_references: ArrayLike | None = None,
                   input_bounds: Bounds | None = None, shift: bool = False, warm_start: WarmStart = None,
                   max_iterations: int = 0, time_limit_ms: float = 0.0, previous_input: ArrayLike | None = None,
                   model: StepModel | None = None) -> Plan:
        """nupmpc.Session.step, awaited."""
        step = build_step(self._spec, x, references=references, bounds=bounds, input_references=input_references,
                          input_bounds=input_bounds, shift=shift, warm_start=warm_start,
                          max_iterations=max_iterations, time_limit_ms=time_limit_ms,
                          previous_input=previous_input, model=model)
        async with self._lock:
            start = time.perf_counter()
            try:
                result = await self._step_once(step)
            except NupmpcError as error:
                if not is_retryable(error):
                    raise
                self._tear_down()
                note = AttemptNote()

                async def attempt(timeout_s: float) -> pb.SolveResult:
                    if self._own_channel:
                        await self._channel.close()
                    self._channel = self._client.new_channel(own_subchannel=True)
                    self._own_channel = True
                    # By its id first (warm), else re-created from the spec (cold), in one
                    # attempt's time.
                    deadline = time.monotonic() + timeout_s
                    await reattach_or_recreate_async(
                        self.id, lambda: self._connect(timeout_s, self.id),
                        lambda: self._connect(max(deadline - time.monotonic(), 0.0)), note)
                    return await self._step_once(step)

                result = await ride_out_outage_async(self._options, error, attempt, self.stats, note)
            round_trip_ms = (time.perf_counter() - start) * 1e3
            apply_step_to_spec(step, result, self._spec)
        return Plan.from_result(result, self._dims, round_trip_ms)

    async def close(self) -> None:
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


class _Finished:
    """A finished call's status in the shape broken_stream_error reads."""

    def __init__(self, code: grpc.StatusCode, details: str | None) -> None:
        self._code, self._details = code, details

    def code(self) -> grpc.StatusCode:
        return self._code

    def details(self) -> str | None:
        return self._details
