"""How a session rides through a broken Control stream (server restart, dropped
connection): bounded retries with exponential back-off and jitter, the semantics of the
C++ client (client/reconnect.h):

    d_k = min(initial_backoff · multiplier^k, max_backoff) · U(1 − jitter, 1 + jitter)

waits between attempts to get the session back, until one succeeds or the `budget`
(from the failure) is spent: no attempt starts after it (the last wait is shortened to
end at it), each attempt is cancelled after `attempt_timeout`, and then the step fails
with Unavailable. Only UNAVAILABLE is retried; other errors are returned at once.

Each attempt asks for the session by its id first (reattach_or_recreate): a server that
kept it, or restored it from its snapshot, hands it back warm; only NOT_FOUND or
FAILED_PRECONDITION make the attempt re-create it from the spec (cold).
"""

from __future__ import annotations

import asyncio
import random
import time
from dataclasses import dataclass, field
from typing import Awaitable, Callable, MutableSequence, Optional, TypeVar

import grpc

from nupmpc.errors import NupmpcError, Unavailable

_Answer = TypeVar("_Answer")
_Got = TypeVar("_Got")


@dataclass
class ReconnectOptions:
    initial_backoff_s: float = 0.05
    multiplier: float = 2.0
    max_backoff_s: float = 2.0
    jitter: float = 0.2
    budget_s: float = 30.0  # per outage; 0: no reconnect at all
    attempt_timeout_s: float = 5.0
    seed: Optional[int] = None  # of the jitter; None: random
    on_attempt: Optional[Callable[[ReconnectAttempt], object]] = None  # called after every attempt
    # Injectable for tests (a fake clock); None: time.monotonic and time.sleep (asyncio
    # sessions always sleep with asyncio.sleep).
    now: Optional[Callable[[], float]] = None
    sleep: Optional[Callable[[float], object]] = None


@dataclass
class ReconnectAttempt:
    attempt: int
    waited_s: float
    elapsed_s: float
    cause: Exception
    error: Optional[Exception]  # None: reconnected
    gave_up: bool
    path: str = "none"  # how the session came back: "reattached", "recreated" or "none"
    attach_by_id: Optional[str] = None  # the attach by id's outcome (a gRPC code name); None: none made


@dataclass
class AttemptNote:
    """What one attempt says about itself, filled in by reattach_or_recreate."""
    path: str = "none"
    attach_by_id: Optional[str] = None


@dataclass
class ReconnectStats:
    reconnects: int = 0      # outages ridden through
    reattached: int = 0      # of them, sessions attached again by their id (warm)
    recreated: int = 0       # of them, sessions re-created from the spec (cold)
    attempts: int = 0
    failed_outages: int = 0  # outages that spent the budget
    total_s: float = 0.0
    longest_s: float = 0.0
    # The attempts (a list; with a period, a deque of the most recent).
    attempt_log: MutableSequence[ReconnectAttempt] = field(default_factory=list)


def is_retryable(error: BaseException | None) -> bool:
    return isinstance(error, NupmpcError) and error.code == grpc.StatusCode.UNAVAILABLE


def attach_by_id_missed(error: BaseException) -> bool:
    """Whether a failed attach by id says the session is not to be had by its id: the
    server neither holds it nor could restore it (NOT_FOUND), or another stream holds it
    (FAILED_PRECONDITION). Waiting cannot help then: re-create it."""
    return isinstance(error, NupmpcError) and error.code in (grpc.StatusCode.NOT_FOUND,
                                                             grpc.StatusCode.FAILED_PRECONDITION)


def reattach_or_recreate(session_id: str | None, attach_by_id: Callable[[], _Got], recreate: Callable[[], _Got],
                         note: AttemptNote) -> _Got:
    """One attempt to get a broken stream's session back: `attach_by_id` when there is an
    id (the warm start survives), `recreate` only when that attach missed
    (attach_by_id_missed). Any other error is the attempt's (UNAVAILABLE: retried by the
    back-off, by id first again). Fills `note`."""
    note.path, note.attach_by_id = "none", None
    if session_id:
        try:
            got = attach_by_id()
        except NupmpcError as error:
            _attach_missed(error, note)
        else:
            note.path, note.attach_by_id = "reattached", "OK"
            return got
    got = recreate()
    note.path = "recreated"
    return got


async def reattach_or_recreate_async(session_id: str | None, attach_by_id: Callable[[], Awaitable[_Got]],
                                     recreate: Callable[[], Awaitable[_Got]], note: AttemptNote) -> _Got:
    """reattach_or_recreate for asyncio: both are coroutine functions."""
    note.path, note.attach_by_id = "none", None
    if session_id:
        try:
            got = await attach_by_id()
        except NupmpcError as error:
            _attach_missed(error, note)
        else:
            note.path, note.attach_by_id = "reattached", "OK"
            return got
    got = await recreate()
    note.path = "recreated"
    return got


def _attach_missed(error: NupmpcError, note: AttemptNote) -> None:
    """Notes a failed attach by id; raises it again unless re-creating is the answer."""
    note.attach_by_id = error.code.name
    if not attach_by_id_missed(error):
        raise error


def count_reconnect(path: str, stats: ReconnectStats) -> None:
    """Books one reconnect that got its session back by `path` (and answered its step)."""
    stats.reconnects += 1
    if path == "reattached":
        stats.reattached += 1
    elif path == "recreated":
        stats.recreated += 1


class Backoff:
    def __init__(self, options: ReconnectOptions) -> None:
        self.options = options
        self.attempt = 0
        self.rng = random.Random(options.seed)

    def nominal_next(self) -> float:
        o = self.options
        return min(max(o.initial_backoff_s, 0.0) * max(o.multiplier, 1.0) ** self.attempt, max(o.max_backoff_s, 0.0))

    def next(self) -> float:
        nominal = self.nominal_next()
        self.attempt += 1
        jitter = min(max(self.options.jitter, 0.0), 1.0)
        return nominal * self.rng.uniform(1.0 - jitter, 1.0 + jitter)


class _Outage:
    """The bookkeeping of one outage, shared by the blocking and the asyncio loop."""

    def __init__(self, options: ReconnectOptions, cause: Exception, stats: ReconnectStats) -> None:
        self.options, self.cause, self.stats = options, cause, stats
        self.now = options.now or time.monotonic
        self.start = self.now()
        self.backoff = Backoff(options)
        self.made = 0

    def elapsed(self) -> float:
        return self.now() - self.start

    def next_wait(self) -> float:
        return min(self.backoff.next(), max(self.options.budget_s - self.elapsed(), 0.0))

    def record(self, wait: float, error: NupmpcError | None, note: AttemptNote) -> bool:
        """Books one attempt; returns True when the loop should stop."""
        self.made += 1
        elapsed = self.elapsed()
        retryable = is_retryable(error)
        gave_up = error is not None and (not retryable or elapsed >= self.options.budget_s)
        report = ReconnectAttempt(self.made, wait, elapsed, self.cause, error, gave_up,
                                  note.path if error is None else "none", note.attach_by_id)
        self.stats.attempt_log.append(report)
        if self.options.on_attempt:
            self.options.on_attempt(report)
        if error is not None:
            self.cause = error
        return error is None or not retryable

    def _finish(self) -> float:
        """Books the outage's attempts and duration; returns the duration."""
        took = self.elapsed()
        self.stats.attempts += self.made
        self.stats.total_s += took
        self.stats.longest_s = max(self.stats.longest_s, took)
        return took

    def answered(self, note: AttemptNote) -> None:
        self._finish()
        # The attempt that got the answer is the last one: its path is the outage's.
        count_reconnect(note.path, self.stats)

    def failed(self, error: NupmpcError | None) -> NupmpcError:
        """The error to raise: `error` itself, or Unavailable once the budget is spent."""
        took = self._finish()
        if error is None or is_retryable(error):
            self.stats.failed_outages += 1
            return Unavailable(f"gave up reconnecting after {self.made} attempt(s) in {took * 1000:.0f} ms "
                               f"(budget {self.options.budget_s * 1000:.0f} ms); last error: {self.cause}")
        return error


def ride_out_outage(options: ReconnectOptions, cause: Exception, reconnect_and_resend: Callable[[float], _Answer],
                    stats: ReconnectStats, note: AttemptNote | None = None) -> _Answer:
    """Retries `reconnect_and_resend(timeout_s)` (get the session back, resend the step;
    returns the answer or raises) with back-off; returns the answer, or raises the error
    that ended the outage (Unavailable once the budget is spent). `note` is what each
    attempt fills in (reattach_or_recreate) to say how it got its session back."""
    note = note or AttemptNote(path="recreated")  # a caller that only re-creates
    outage = _Outage(options, cause, stats)
    sleep = options.sleep or time.sleep
    error = None
    while outage.elapsed() < options.budget_s:
        wait = outage.next_wait()
        if wait > 0:
            sleep(wait)
        try:
            answer = reconnect_and_resend(options.attempt_timeout_s)
        except NupmpcError as e:
            error = e
            if outage.record(wait, e, note):
                break
            continue
        outage.record(wait, None, note)
        outage.answered(note)
        return answer
    raise outage.failed(error)


async def ride_out_outage_async(options: ReconnectOptions, cause: Exception,
                                reconnect_and_resend: Callable[[float], Awaitable[_Answer]],
                                stats: ReconnectStats, note: AttemptNote | None = None) -> _Answer:
    """ride_out_outage for asyncio: `reconnect_and_resend` is a coroutine function."""
    note = note or AttemptNote(path="recreated")
    outage = _Outage(options, cause, stats)
    error = None
    while outage.elapsed() < options.budget_s:
        wait = outage.next_wait()
        if wait > 0:
            await asyncio.sleep(wait)
        try:
            answer = await reconnect_and_resend(options.attempt_timeout_s)
        except NupmpcError as e:
            error = e
            if outage.record(wait, e, note):
                break
            continue
        outage.record(wait, None, note)
        outage.answered(note)
        return answer
    raise outage.failed(error)
