"""The reconnect back-off on a fake clock: the expectations of the C++ client's
tests/client/reconnect_test.cc, so both clients ride out an outage the same way."""

import pytest

import nupmpc
from nupmpc.reconnect import Backoff, ReconnectOptions, ReconnectStats, is_retryable, ride_out_outage


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
