"""The client: one channel to a server, unary calls, and sessions (Control streams).

    with nupmpc.connect("127.0.0.1:50051", token=...) as client:
        plan = client.solve_once(problem)
        session = client.session(problem)
"""

from __future__ import annotations

import time
import weakref
from types import TracebackType
from typing import TYPE_CHECKING, Any, Callable, ClassVar, TypeVar, Union

import grpc

from nupmpc._proto import pb, pb_grpc
from nupmpc.errors import error_from_rpc
from nupmpc.spec_builder import _Spec
from nupmpc.result import Plan
from nupmpc.security import channel_credentials, channel_options
from nupmpc.step import dims_of

if TYPE_CHECKING:
    from nupmpc.reconnect import ReconnectOptions
    from nupmpc.session import Session

# What a session or a solve is made from: a builder (Problem, GpProblem) or a ProblemSpec.
ProblemLike = Union[_Spec, pb.ProblemSpec]
_Reply = TypeVar("_Reply")


def spec_of(problem: ProblemLike) -> pb.ProblemSpec:
    """The ProblemSpec of a builder (Problem, GpProblem) or of a ProblemSpec itself."""
    if isinstance(problem, _Spec):
        return problem.spec
    if isinstance(problem, pb.ProblemSpec):
        return problem
    raise TypeError(f"problem: expected a nupmpc.Problem, GpProblem or ProblemSpec, got {type(problem).__name__}")


class _Connection:
    """What the blocking and the asyncio client share: the target, credentials checked up
    front, and channels made with them. Subclasses say how a channel is opened."""

    # grpc.insecure_channel and grpc.secure_channel, or their grpc.aio twins (untyped).
    _insecure_channel: ClassVar[Any]
    _secure_channel: ClassVar[Any]

    def __init__(self, target: str, tls: bool = False, ca_file: str | None = None, cert_file: str | None = None,
                 key_file: str | None = None, server_name: str | None = None, token: str | None = None,
                 deadline_s: float | None = None) -> None:
        self.target = target
        self.deadline_s = deadline_s
        self._credentials = channel_credentials(target, tls=tls, ca_file=ca_file, cert_file=cert_file,
                                                key_file=key_file, token=token)
        self._server_name = server_name
        self._channel = self.new_channel()
        self._stub = pb_grpc.MpcServiceStub(self._channel)
        self._sessions: weakref.WeakSet[Any] = weakref.WeakSet()  # closed with the client, if still alive

    def new_channel(self, own_subchannel: bool = False) -> Any:
        """A channel to the target with this client's credentials (own_subchannel: a
        connection of its own, for a session's reconnect attempts)."""
        options = channel_options(self._server_name, own_subchannel)
        if self._credentials is None:
            return type(self)._insecure_channel(self.target, options=options)
        return type(self)._secure_channel(self.target, self._credentials, options=options)


class Client(_Connection):
    """A connection to nupmpc-server. `deadline_s` bounds each unary call (None: none)."""

    _insecure_channel = staticmethod(grpc.insecure_channel)
    _secure_channel = staticmethod(grpc.secure_channel)

    _sessions: weakref.WeakSet[Session]

    def _call(self, method: Callable[..., _Reply], request: object) -> _Reply:
        try:
            return method(request, timeout=self.deadline_s)
        except grpc.RpcError as error:
            raise error_from_rpc(error) from None

    def solve_once(self, problem: ProblemLike) -> Plan:
        """One stateless solve (SolveOnce) → Plan."""
        spec = spec_of(problem)
        start = time.perf_counter()
        response: pb.SolveOnceResponse = self._call(self._stub.SolveOnce, pb.SolveOnceRequest(spec=spec))
        return Plan.from_result(response.result, dims_of(spec), (time.perf_counter() - start) * 1e3)

    def session(self, problem: ProblemLike, reconnect: ReconnectOptions | None = None, period: float | None = None,
                held_periods: int | None = None) -> Session:
        """A session on a Control stream that owns it (closed with the stream); it
        re-creates itself after a server restart. period: the control period in seconds, by
        which every step returns, held when its answer has not come (see nupmpc.Session)."""
        from nupmpc.session import Session
        session = Session(self, spec_of(problem), reconnect, period, held_periods)
        self._sessions.add(session)
        return session

    def server_info(self) -> pb.GetServerInfoResponse:
        """GetServerInfoResponse (version, limits, counters)."""
        info: pb.GetServerInfoResponse = self._call(self._stub.GetServerInfo, pb.GetServerInfoRequest())
        return info

    def fit_gp_model(self, model: pb.GpModel, max_iterations: int = 0) -> pb.FitGpModelResponse:
        """FitGpModelResponse for a pb.GpModel (its .kernel is the fitted one)."""
        fit: pb.FitGpModelResponse = self._call(self._stub.FitGpModel,
                                                pb.FitGpModelRequest(model=model, max_iterations=max_iterations))
        return fit

    def list_sessions(self) -> list[pb.SessionInfo]:
        listed: pb.ListSessionsResponse = self._call(self._stub.ListSessions, pb.ListSessionsRequest())
        return list(listed.sessions)

    def close(self) -> None:
        for session in list(self._sessions):
            session.close()
        self._sessions.clear()
        self._channel.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def connect(target: str, tls: bool = False, ca_file: str | None = None, cert_file: str | None = None,
            key_file: str | None = None, server_name: str | None = None, token: str | None = None,
            deadline_s: float | None = None) -> Client:
    """A Client of the server at `target` ("host:port", "unix:/path"). tls: verify against
    the system CAs (or ca_file); cert_file + key_file: mTLS; server_name: the name the
    certificate must carry; token: sent as `authorization: Bearer TOKEN` (over TLS, or to a
    loopback/Unix target only)."""
    return Client(target, tls=tls, ca_file=ca_file, cert_file=cert_file, key_file=key_file,
                  server_name=server_name, token=token, deadline_s=deadline_s)
