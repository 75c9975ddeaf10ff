"""A session on a Control stream (the main path), riding through server restarts and
quiet network failures. The semantics of the C++ client (client/session.h):

Without a period, a step waits for its answer. When its stream breaks (UNAVAILABLE, a
cancellation it did not make, a stream that ended without a status or without an error)
the step gets its session back with back-off (nupmpc.reconnect): attached again by its id
when the server kept or restored it (warm), else re-created from the spec it holds (kept
current with every answered step, nupmpc.spec_update; cold), and resends itself, so step()
returns that step's plan; only a spent budget makes it raise Unavailable.

With a control period P (`period=` in seconds), step() returns by P after it was called,
whatever the network does: with the plan if the answer came, else a Plan with `held`
True (status HELD, no plan: hold the last input or apply a fallback). A late answer is
never returned for a later step (answers are matched by sequence number); it only keeps
the spec current. After K held steps in a row (K = max(3, ceil(1 s / P)) unless given)
the stream counts as broken, as it does when it ends, and a background thread gets the
session back the same way for as long as the caller keeps stepping: no overall budget, back-off at most
0.5 s, each attempt cancelled after at most 1 s; steps meanwhile are held. The slack: a
step returns within P plus the time to wake its thread (tests allow 100 ms and more).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from types import TracebackType
from typing import TYPE_CHECKING, overload

import grpc

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike
from nupmpc.control_call import _Stream, attach
from nupmpc.errors import NupmpcError, Unavailable, error_from_code
from nupmpc.reconnect import AttemptNote, Backoff, ReconnectAttempt, ReconnectOptions, ReconnectStats, \
    count_reconnect, is_retryable, reattach_or_recreate, ride_out_outage
from nupmpc.result import Plan, held_result
from nupmpc.spec_update import apply_step_to_spec
from nupmpc.step import Bounds, Dims, StepModel, WarmStart, build_step, dims_of

if TYPE_CHECKING:
    from nupmpc.client import Client

# With a period: the caps on the reconnect options, and how recent the last step must be
# for the reconnect thread to keep trying.
MAX_BACKOFF_S = 0.5
MAX_ATTEMPT_TIMEOUT_S = 1.0
STEPPING_S = 1.0
# Sent steps whose answer has not come that are remembered (for the spec) at most (and at
# least 2 K: past K the stream counts as broken anyway).
MAX_UNANSWERED = 256
# Reconnect attempts kept in stats.attempt_log with a period (no overall budget: an outage
# may last for ever).
ATTEMPT_LOG_LENGTH = 100


def held_periods_to_reconnect(period_s: float, given: int | None = None) -> int:
    """K: held steps in a row after which the stream counts as broken."""
    if given is not None:
        if int(given) != given or given < 1:
            raise ValueError(f"held_periods: must be an integer >= 1, got {given!r}")
        return int(given)
    return max(3, math.ceil(1.0 / period_s))


class Session:
    """session.step(x, ...) → Plan, one control period; see step() for the arguments.

    period: the control period in seconds (None: a step waits for its answer); see the
    module text. held_periods: K (None: max(3, ceil(1 s / period)))."""

    def __init__(self, client: Client, spec: pb.ProblemSpec, reconnect: ReconnectOptions | None = None,
                 period: float | None = None, held_periods: int | None = None) -> None:
        if period is not None and not period > 0:
            raise ValueError(f"period: must be > 0 seconds, got {period!r}")
        self._client = client
        self._spec = pb.ProblemSpec()
        self._spec.CopyFrom(spec)
        # The server learns the period as the session's deadline (ProblemSpec.timing),
        # unless the spec sets one of its own.
        if period and not self._spec.timing.period_ms:
            self._spec.timing.period_ms = period * 1e3
        self._dims = dims_of(spec)
        self._options = reconnect or ReconnectOptions()
        self._period = period
        self._held_periods = held_periods_to_reconnect(period, held_periods) if period else 0  # K; 0: no period
        self._step_lock = threading.Lock()  # one step (or close) at a time
        self._cond = threading.Condition()  # everything below
        self._channel = client._channel
        self._own_channel = False
        self._stream: _Stream | None = None
        self._sequence = 1
        self._unanswered: dict[int, pb.Step] = {}  # sequence → step sent and not answered yet
        self.id: str | None = None
        self.stats = ReconnectStats()
        self.held_steps = 0
        self.consecutive_held = 0
        self.late_answers = 0
        self._unreported_held = 0
        self._silent_periods = 0  # held periods in a row without any answer (the K rule)
        self._closing = False
        # Why the stream counts as broken (the reconnect attempts report it); set by every break.
        self._break_cause: NupmpcError = Unavailable("the Control stream broke")
        self._broken_at = self._last_step_at = time.monotonic()
        with self._cond:
            self._stream, self.id = attach(self._channel, self._spec, self._next_sequence(),
                                            self._options.attempt_timeout_s)
        self._reconnector: threading.Thread | None = None
        if period:
            self.stats.attempt_log = deque(maxlen=ATTEMPT_LOG_LENGTH)
            self._reconnector = threading.Thread(target=self._reconnect_loop, args=(period,), daemon=True)
            self._reconnector.start()

    @property
    def spec(self) -> pb.ProblemSpec:
        """The spec the session would be re-created from (kept current with every step)."""
        with self._cond:
            copy = pb.ProblemSpec()
            copy.CopyFrom(self._spec)
        return copy

    @property
    def dims(self) -> Dims:
        """(M, L, K, N)."""
        return self._dims

    @property
    def period(self) -> float | None:
        return self._period

    @property
    def reconnects(self) -> int:
        return self.stats.reconnects

    def _next_sequence(self) -> int:
        sequence = self._sequence
        self._sequence += 1
        return sequence

    def _renew_channel(self) -> None:
        # A channel whose connection attempts were refused while the server was down keeps
        # failing calls at once until its own back-off (1 s growing ×1.6) lets it retry:
        # every attempt gets a new channel with a connection of its own. Under _cond.
        if self._own_channel:
            self._channel.close()
        self._channel = self._client.new_channel(own_subchannel=True)
        self._own_channel = True

    def _take_late_answer(self, response: pb.ControlResponse) -> None:
        with self._cond:
            self._silent_periods = 0  # the stream is alive, only slower than the period
            step = self._unanswered.get(response.sequence)
            if step is None:
                return
            self.late_answers += 1
            if response.error_code != 0 or response.result.status == pb.SOLVE_STATUS_SUPERSEDED:
                # A refusal or a SUPERSEDED answer comes at once, ahead of the solve in
                # progress of an earlier step: only this step is settled, nothing applied.
                del self._unanswered[response.sequence]
                return
            # The server applied the step: so does the spec. Solves run one at a time and
            # answers of earlier steps were sent before this one's: none is still to come.
            apply_step_to_spec(step, response.result, self._spec)
            for sequence in [s for s in self._unanswered if s <= response.sequence]:
                del self._unanswered[sequence]

    @overload
    def _exchange(self, step: pb.Step, deadline: None) -> pb.SolveResult: ...

    @overload
    def _exchange(self, step: pb.Step, deadline: float) -> pb.SolveResult | None: ...

    def _exchange(self, step: pb.Step, deadline: float | None) -> pb.SolveResult | None:
        """Sends `step` and waits for its answer until `deadline` (None: no deadline):
        the result, None (held), or raises the step's or the stream's error."""
        with self._cond:
            stream = self._stream
            if stream is None:
                raise Unavailable("not connected")
            sequence = self._next_sequence()
            self._unanswered[sequence] = step
            if len(self._unanswered) > max(MAX_UNANSWERED, 2 * self._held_periods):
                del self._unanswered[min(self._unanswered)]
            dropped = stream.send(pb.ControlRequest(sequence=sequence, step=step,
                                                    held_periods=self._unreported_held))
            self._unreported_held = 0
            if dropped is not None:
                self._unanswered.pop(dropped, None)  # never sent: nothing of it applies
        while True:
            try:
                response = stream.receive("read", deadline)
            except NupmpcError as error:
                with self._cond:
                    self._break(stream, error)  # the session is gone with its stream
                raise
            if response is None:
                return None  # held: the answer may still come
            if response.sequence != sequence:
                self._take_late_answer(response)
                continue
            with self._cond:
                self._silent_periods = 0
                self._unanswered.pop(sequence, None)
                if response.error_code != 0:
                    raise error_from_code(response.error_code, response.error_message)
                apply_step_to_spec(step, response.result, self._spec)
            return response.result

    def _step_waiting(self, step: pb.Step) -> pb.SolveResult:
        try:
            return self._exchange(step, None)
        except NupmpcError as error:
            if not is_retryable(error):
                raise
            cause = error
        with self._cond:
            self._drop_stream()

        note = AttemptNote()

        def reconnect_and_resend(timeout_s: float) -> pb.SolveResult:
            with self._cond:
                self._renew_channel()
                self._stream, self.id = self._attach(self._channel, self.id, self._spec, self._next_sequence(),
                                                     timeout_s, note)
            # Resent once per attempt that got a session, on its new stream only; the answer
            # is matched by the new sequence number, so the plan returned is this step's.
            try:
                return self._exchange(step, None)
            except NupmpcError as e:
                if is_retryable(e):
                    with self._cond:
                        self._drop_stream()
                raise
        return ride_out_outage(self._options, cause, reconnect_and_resend, self.stats, note)

    @staticmethod
    def _attach(channel: grpc.Channel, session_id: str | None, spec: pb.ProblemSpec, sequence: int,
                timeout_s: float, note: AttemptNote) -> tuple[_Stream, str]:
        """A stream attached to `session_id` (warm), or, when the server no longer has it,
        to a session created from `spec`; both within one timeout. Fills `note`."""
        deadline = time.monotonic() + timeout_s
        return reattach_or_recreate(
            session_id,
            lambda: attach(channel, spec, sequence, timeout_s, session_id=session_id),
            lambda: attach(channel, spec, sequence, max(deadline - time.monotonic(), 0.0)),
            note)

    def _drop_stream(self) -> None:
        if self._stream is not None:
            self._stream.cancel()
            self._stream = None

    def _break(self, stream: _Stream, cause: NupmpcError) -> None:
        """The stream `stream` counts as broken: dropped, and the reconnect thread woken. Under _cond."""
        if self._stream is None or self._stream is not stream:
            return  # already broken (and maybe replaced)
        self._drop_stream()
        self._unanswered.clear()
        self._break_cause, self._broken_at = cause, time.monotonic()
        self._cond.notify_all()

    def _step_in_period(self, step: pb.Step, deadline: float) -> pb.SolveResult:
        with self._cond:
            self._last_step_at = time.monotonic()
            if self._stream is not None and self._stream.ended:
                self._break(self._stream, Unavailable("the Control stream ended"))
            # Wake the reconnect thread (it pauses while nobody steps), then wait for it as
            # long as the period allows.
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._stream is not None or self._closing,
                                timeout=max(deadline - time.monotonic(), 0.0))
            stream = self._stream
        result = None
        if stream is not None:
            try:
                result = self._exchange(step, deadline)
            except NupmpcError as error:
                if not is_retryable(error):
                    raise  # the step's own error (a bad update): not a held period
                with self._cond:
                    self._break(stream, error)
        with self._cond:
            if result is not None:
                self.consecutive_held = 0
                return result
            self.held_steps += 1
            self.consecutive_held += 1
            self._unreported_held += 1  # told the server with the next step (ControlRequest.held_periods)
            # Late answers reset _silent_periods: a live server slower than the period keeps
            # its stream (and its warm start); only one that answers nothing is left.
            if stream is not None:
                self._silent_periods += 1
                if self._silent_periods >= self._held_periods:
                    self._break(stream, Unavailable(f"no answer in {self._silent_periods} periods in a row"))
        return held_result()

    def _reconnect_loop(self, period: float) -> None:
        o = self._options
        options = ReconnectOptions(initial_backoff_s=o.initial_backoff_s, multiplier=o.multiplier,
                                   max_backoff_s=min(o.max_backoff_s, MAX_BACKOFF_S), jitter=o.jitter,
                                   attempt_timeout_s=min(o.attempt_timeout_s, MAX_ATTEMPT_TIMEOUT_S), seed=o.seed)
        stepping_s = max(STEPPING_S, 2 * period)
        backoff, attempt = Backoff(options), 0
        with self._cond:
            while True:
                self._cond.wait_for(lambda: self._closing or (
                    self._stream is None and time.monotonic() - self._last_step_at < stepping_s))
                if self._closing:
                    return
                if attempt == 0:
                    backoff = Backoff(options)
                # Capped after the jitter too: at most MAX_BACKOFF_S between attempts.
                wait = min(backoff.next(), MAX_BACKOFF_S)
                if self._cond.wait_for(lambda: self._closing, timeout=wait):
                    return
                self._renew_channel()
                channel, spec, sequence, old_id = self._channel, pb.ProblemSpec(), self._next_sequence(), self.id
                spec.CopyFrom(self._spec)
                note = AttemptNote()
                self._cond.release()
                try:
                    stream, session_id = self._attach(channel, old_id, spec, sequence, options.attempt_timeout_s, note)
                    error = None
                except Exception as e:  # noqa: BLE001 - a channel closed under it too: the thread must live on
                    stream, error = None, e if isinstance(e, NupmpcError) else Unavailable(f"reconnect attempt: {e}")
                    error.__traceback__ = None  # kept in the attempt log: no frames with it
                finally:
                    self._cond.acquire()
                attempt += 1
                elapsed = time.monotonic() - self._broken_at
                self.stats.attempts += 1
                if error is None and not self._closing:
                    self._stream, self.id = stream, session_id
                    self._silent_periods, attempt = 0, 0
                    count_reconnect(note.path, self.stats)
                    self.stats.total_s += elapsed
                    self.stats.longest_s = max(self.stats.longest_s, elapsed)
                    self._cond.notify_all()
                elif stream is not None:
                    stream.cancel()
                report = ReconnectAttempt(attempt, wait, elapsed, self._break_cause, error, False,
                                          note.path if error is None else "none", note.attach_by_id)
                self.stats.attempt_log.append(report)
                if error is not None:
                    self._break_cause = error
                if o.on_attempt:
                    # Not under the lock: a slow callback must not hold the steps up.
                    self._cond.release()
                    try:
                        o.on_attempt(report)
                    except Exception:  # noqa: BLE001 - the caller's callback must not end reconnecting
                        pass
                    finally:
                        self._cond.acquire()

    def step(self, x: ArrayLike | None = None, *, references: ArrayLike | None = None, bounds: Bounds | None = None,
             input_references: ArrayLike | None = None, input_bounds: Bounds | None = None, shift: bool = False,
             warm_start: WarmStart = None, max_iterations: int = 0, time_limit_ms: float = 0.0,
             previous_input: ArrayLike | None = None, model: StepModel | None = None,
             deadline: float | None = None) -> Plan:
        """Solves one period for the measured state `x` (M,) and returns its Plan; everything
        after `x` is given by keyword.

        references: output references, (K,) or (N+1, K) (GP sessions: r, 1 or N values);
        bounds: (lower, upper) of the outputs, each (K,) or (N+1, K), None for a side kept;
        input_references, input_bounds: the same for the inputs ((L,) or (N, L));
        shift: move every stored per-step prior one step first (receding references);
        warm_start: None/"shift", "keep" or "cold"; previous_input: u[-1] (Δu problems);
        model: new model terms for this period (a nupmpc.ModelUpdate; a pb.ModelUpdate is
        sent unchecked), kept for later steps as the prior updates are;
        deadline: with a period, the time.monotonic() by which to return instead of one
        period from now (a caller that makes several steps within one period).
        Raises ShapeError (before sending) or a typed NupmpcError from the server."""
        step = build_step(self._spec, x, references=references, bounds=bounds, input_references=input_references,
                          input_bounds=input_bounds, shift=shift, warm_start=warm_start,
                          max_iterations=max_iterations, time_limit_ms=time_limit_ms,
                          previous_input=previous_input, model=model)
        if self._period and deadline is not None:
            # The server's deadline for it too (Step.budget_ms), instead of the session's period.
            step.budget_ms = max((deadline - time.monotonic()) * 1e3, 1e-3)
        with self._step_lock:
            if self._closing:
                raise error_from_code(grpc.StatusCode.FAILED_PRECONDITION, "the session was closed")
            start = time.perf_counter()
            if self._period:
                result = self._step_in_period(step, deadline or time.monotonic() + self._period)
            else:
                result = self._step_waiting(step)
            round_trip_ms = (time.perf_counter() - start) * 1e3
        return Plan.from_result(result, self._dims, round_trip_ms)

    def close(self) -> None:
        """Ends the stream (the server closes the session); later steps raise. With a
        period, returns within about two seconds (a reconnect attempt in flight ends first,
        then the server's goodbye is awaited for a second)."""
        with self._step_lock:
            with self._cond:
                self._closing = True
                self._cond.notify_all()
            if self._reconnector is not None:
                self._reconnector.join()
        with self._step_lock, self._cond:
            if self._stream is not None:
                self._stream.close(1.0 if self._period else None)
                self._stream = None
            if self._own_channel:
                self._channel.close()
                self._own_channel = False

    def __enter__(self) -> Session:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()
