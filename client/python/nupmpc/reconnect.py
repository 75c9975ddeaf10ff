"""How a session rides through a broken Control stream (server restart, dropped
connection): bounded retries with exponential back-off and jitter, the semantics of the
C++ client (client/reconnect.h):

    d_k = min(initial_backoff · multiplier^k, max_backoff) · U(1 − jitter, 1 + jitter)

waits between attempts to re-create the session, until one succeeds or the `budget`
(from the failure) is spent: no attempt starts after it (the last wait is shortened to
end at it), each attempt is cancelled after `attempt_timeout`, and then the step fails
with Unavailable. Only UNAVAILABLE is retried; other errors are returned at once.
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


@dataclass
class ReconnectStats:
    reconnects: int = 0      # outages ridden through
    attempts: int = 0
    failed_outages: int = 0  # outages that spent the budget
    total_s: float = 0.0
    longest_s: float = 0.0
    # The attempts (a list; with a period, a deque of the most recent).
    attempt_log: MutableSequence[ReconnectAttempt] = field(default_factory=list)


def is_retryable(error: BaseException | None) -> bool:
    return isinstance(error, NupmpcError) and error.code == grpc.StatusCode.UNAVAILABLE


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

    def record(self, wait: float, error: NupmpcError | None) -> bool:
        """Books one attempt; returns True when the loop should stop."""
        self.made += 1
        elapsed = self.elapsed()
        retryable = is_retryable(error)
        gave_up = error is not None and (not retryable or elapsed >= self.options.budget_s)
        report = ReconnectAttempt(self.made, wait, elapsed, self.cause, error, gave_up)
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

    def answered(self) -> None:
        self._finish()
        self.stats.reconnects += 1

    def failed(self, error: NupmpcError | None) -> NupmpcError:
        """The error to raise: `error` itself, or Unavailable once the budget is spent."""
        took = self._finish()
        if error is None or is_retryable(error):
            self.stats.failed_outages += 1
            return Unavailable(f"gave up reconnecting after {self.made} attempt(s) in {took * 1000:.0f} ms "
                               f"(budget {self.options.budget_s * 1000:.0f} ms); last error: {self.cause}")
        return error


def ride_out_outage(options: ReconnectOptions, cause: Exception, recreate_and_resend: Callable[[float], _Answer],
                    stats: ReconnectStats) -> _Answer:
    """Retries `recreate_and_resend(timeout_s)` (re-create the session, resend the step;
    returns the answer or raises) with back-off; returns the answer, or raises the error
    that ended the outage (Unavailable once the budget is spent)."""
    outage = _Outage(options, cause, stats)
    sleep = options.sleep or time.sleep
    error = None
    while outage.elapsed() < options.budget_s:
        wait = outage.next_wait()
        if wait > 0:
            sleep(wait)
        try:
            answer = recreate_and_resend(options.attempt_timeout_s)
        except NupmpcError as e:
            error = e
            if outage.record(wait, e):
                break
            continue
        outage.record(wait, None)
        outage.answered()
        return answer
    raise outage.failed(error)


async def ride_out_outage_async(options: ReconnectOptions, cause: Exception,
                                recreate_and_resend: Callable[[float], Awaitable[_Answer]],
                                stats: ReconnectStats) -> _Answer:
    """ride_out_outage for asyncio: `recreate_and_resend` is a coroutine function."""
    outage = _Outage(options, cause, stats)
    error = None
    while outage.elapsed() < options.budget_s:
        wait = outage.next_wait()
        if wait > 0:
            await asyncio.sleep(wait)
        try:
            answer = await recreate_and_resend(options.attempt_timeout_s)
        except NupmpcError as e:
            error = e
            if outage.record(wait, e):
                break
            continue
        outage.record(wait, None)
        outage.answered()
        return answer
    raise outage.failed(error)
