"""The reconnect back-off on a fake clock: the expectations of the C++ client's
tests/client/reconnect_test.cc, so both clients ride out an outage the same way."""

import pytest

import nupmpc
from nupmpc.reconnect import AttemptNote, Backoff, ReconnectOptions, ReconnectStats, attach_by_id_missed, \
    is_retryable, reattach_or_recreate, ride_out_outage


class FakeTime:
    def __init__(self):
        self.t = 0.0
        self.sleeps = []

    def now(self):
        return self.t

    def sleep(self, d):
        self.sleeps.append(d)
        self.t += d


def test_backoff_grows_by_the_factor_up_to_the_cap_without_jitter():
    backoff = Backoff(ReconnectOptions(jitter=0.0))
    assert [round(backoff.next() * 1000) for _ in range(9)] == [50, 100, 200, 400, 800, 1600, 2000, 2000, 2000]


def test_jitter_stays_within_its_range_and_varies():
    backoff = Backoff(ReconnectOptions(seed=7))
    waits = []
    for _ in range(12):
        nominal = backoff.nominal_next()
        wait = backoff.next()
        assert 0.8 * nominal <= wait <= 1.2 * nominal and wait <= 2.4
        waits.append(wait)
    assert len(set(waits)) == len(waits)


def test_unavailable_is_retried_until_it_succeeds():
    time = FakeTime()
    reported = []
    options = ReconnectOptions(jitter=0.0, now=time.now, sleep=time.sleep, on_attempt=reported.append)
    results = iter([nupmpc.Unavailable("connection refused")] * 3 + ["answer"])

    def attempt(timeout_s):
        assert timeout_s == options.attempt_timeout_s
        result = next(results)
        if isinstance(result, Exception):
            raise result
        return result

    stats = ReconnectStats()
    assert ride_out_outage(options, nupmpc.Unavailable("stream broke"), attempt, stats) == "answer"
    assert [round(s * 1000) for s in time.sleeps] == [50, 100, 200, 400]
    assert reported[0].cause.details == "stream broke" and reported[1].cause.details == "connection refused"
    assert reported[3].error is None and round(reported[3].elapsed_s * 1000) == 750 and not reported[3].gave_up
    assert (stats.reconnects, stats.attempts, stats.failed_outages) == (1, 4, 0)


def test_the_budget_stops_the_retries_shortening_the_last_wait():
    time = FakeTime()
    reported = []
    options = ReconnectOptions(budget_s=3.0, seed=3, now=time.now, sleep=time.sleep, on_attempt=reported.append)

    def attempt(timeout_s):
        raise nupmpc.Unavailable("connection refused")

    stats = ReconnectStats()
    with pytest.raises(nupmpc.Unavailable) as caught:
        ride_out_outage(options, nupmpc.Unavailable("stream broke"), attempt, stats)
    assert "gave up reconnecting" in str(caught.value) and "connection refused" in str(caught.value)
    assert 3.0 <= sum(time.sleeps) <= 3.005
    assert len(reported) >= 5 and reported[-1].gave_up and not any(r.gave_up for r in reported[:-1])
    assert all(b > a for a, b in zip(time.sleeps[:-2], time.sleeps[1:-1]))
    assert stats.failed_outages == 1 and stats.reconnects == 0


def test_what_retrying_cannot_fix_is_returned_at_once():
    time = FakeTime()
    calls = []

    def attempt(timeout_s):
        calls.append(timeout_s)
        raise nupmpc.InvalidArgument("spec.model.a[0]: not square")

    with pytest.raises(nupmpc.InvalidArgument):
        ride_out_outage(ReconnectOptions(now=time.now, sleep=time.sleep), nupmpc.Unavailable("x"), attempt,
                        ReconnectStats())
    assert len(calls) == 1
    assert is_retryable(nupmpc.Unavailable("x"))
    assert not is_retryable(nupmpc.InvalidArgument("x")) and not is_retryable(nupmpc.DeadlineExceeded("x"))


def test_a_zero_budget_makes_no_attempt():
    time = FakeTime()
    calls = []
    with pytest.raises(nupmpc.Unavailable):
        ride_out_outage(ReconnectOptions(budget_s=0.0, now=time.now, sleep=time.sleep), nupmpc.Unavailable("x"),
                        lambda t: calls.append(t), ReconnectStats())
    assert calls == [] and time.sleeps == []


class ScriptedAttempt:
    """An attempt whose attach by id and re-creation answer as the test says (an exception
    is raised, anything else returned), counting the calls."""

    def __init__(self, attach, create="created"):
        self.attach, self.create = attach, create
        self.attaches = self.creates = 0

    def _attach(self):
        self.attaches += 1
        if isinstance(self.attach, Exception):
            raise self.attach
        return self.attach

    def _create(self):
        self.creates += 1
        if isinstance(self.create, Exception):
            raise self.create
        return self.create

    def run(self, session_id, note):
        return reattach_or_recreate(session_id, self._attach, self._create, note)


def test_a_session_handed_back_is_reattached_without_recreating():
    attempt, note = ScriptedAttempt("attached"), AttemptNote()
    assert attempt.run("id", note) == "attached"
    assert (attempt.attaches, attempt.creates) == (1, 0)
    assert (note.path, note.attach_by_id) == ("reattached", "OK")


@pytest.mark.parametrize("missed", [nupmpc.NotFound("no such session"),
                                    nupmpc.FailedPrecondition("another Control stream is attached to it")])
def test_not_found_or_held_elsewhere_recreates_in_the_same_attempt(missed):
    attempt, note = ScriptedAttempt(missed), AttemptNote()
    assert attempt.run("id", note) == "created"
    assert (attempt.attaches, attempt.creates) == (1, 1)
    assert (note.path, note.attach_by_id) == ("recreated", missed.code.name)
    # A re-creation that fails is the attempt's error; nothing came back.
    refused = ScriptedAttempt(missed, nupmpc.Unavailable("connection refused"))
    with pytest.raises(nupmpc.Unavailable):
        refused.run("id", note)
    assert note.path == "none"


@pytest.mark.parametrize("error", [nupmpc.Unavailable("restarting"), nupmpc.PermissionDenied("no"),
                                   nupmpc.Unauthenticated("no token")])
def test_other_errors_are_the_attempts_and_recreate_nothing(error):
    attempt, note = ScriptedAttempt(error), AttemptNote()
    with pytest.raises(type(error)):
        attempt.run("id", note)
    assert attempt.creates == 0 and note.path == "none"
    assert not attach_by_id_missed(error)
    assert attach_by_id_missed(nupmpc.NotFound("x")) and attach_by_id_missed(nupmpc.FailedPrecondition("x"))


def test_without_an_id_it_creates():
    attempt, note = ScriptedAttempt("attached"), AttemptNote()
    assert attempt.run(None, note) == "created"
    assert (attempt.attaches, attempt.creates, note.path, note.attach_by_id) == (0, 1, "recreated", None)


@pytest.mark.parametrize("kept", [True, False])
def test_an_outage_is_booked_by_how_the_session_came_back(kept):
    """Down for two attempts, then the attach by id answers as `kept` says: the step is
    resent only by the attempt that got the session back."""
    time = FakeTime()
    reported = []
    options = ReconnectOptions(jitter=0.0, now=time.now, sleep=time.sleep, on_attempt=reported.append)
    note, stats = AttemptNote(), ReconnectStats()
    calls, resent = [0], [0]

    def attempt(timeout_s):
        calls[0] += 1
        attach = nupmpc.Unavailable("connection refused") if calls[0] < 3 else \
            "attached" if kept else nupmpc.NotFound("no such session")
        ScriptedAttempt(attach).run("id", note)
        resent[0] += 1
        return "answer"

    assert ride_out_outage(options, nupmpc.Unavailable("stream broke"), attempt, stats, note) == "answer"
    assert resent[0] == 1 and stats.attempts == 3 and stats.reconnects == 1
    assert (stats.reattached, stats.recreated) == ((1, 0) if kept else (0, 1))
    assert [r.path for r in reported] == ["none", "none", "reattached" if kept else "recreated"]
    assert reported[0].attach_by_id == "UNAVAILABLE"
