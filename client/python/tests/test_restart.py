"""A server restart mid-loop is ridden through: SIGKILL the server, start a new one on
the same port, and the loop goes on; every step's plan is for the state sent."""

import asyncio
import threading

import numpy as np

import nupmpc
from conftest import ServerProcess


def _restart_soon(server, delay_s):
    """Kills the server now and starts it again after delay_s (in the background)."""
    server.kill()
    restarter = threading.Timer(delay_s, server.start)
    restarter.start()
    return restarter


def test_a_session_rides_through_a_server_restart(masses, reference):
    j_star = reference["masses_N30"]["closed_loop"]["J_star"]
    server = ServerProcess()
    attempts = []
    try:
        with nupmpc.connect(server.target) as client:
            session = client.session(masses.problem, nupmpc.ReconnectOptions(on_attempt=attempts.append, seed=1))
            first_id = session.id
            restarter = None
            for t, x in enumerate(masses.closed_loop_states[:40]):
                if t == 15:
                    restarter = _restart_soon(server, 0.3)  # down while the step is sent
                plan = session.step(x)
                np.testing.assert_array_equal(plan.x[0], x)
                assert plan.converged, t
                assert abs(plan.objective - j_star[t]) <= 1e-6 * abs(j_star[t]), t
            restarter.join()
            assert session.reconnects == 1
            assert session.id != first_id  # re-created under a new id
            assert attempts[-1].error is None and len(attempts) >= 2  # refused while down, then back
            assert session.stats.failed_outages == 0
            session.close()
    finally:
        server.stop()


def test_a_spent_budget_raises_unavailable(masses):
    server = ServerProcess()
    try:
        with nupmpc.connect(server.target) as client:
            session = client.session(masses.problem, nupmpc.ReconnectOptions(budget_s=0.3, seed=1))
            session.step(masses.closed_loop_states[0])
            server.kill()
            try:
                session.step(masses.closed_loop_states[1])
            except nupmpc.Unavailable as error:
                assert "gave up reconnecting" in str(error)
            else:
                raise AssertionError("a step to a dead server returned")
            assert session.stats.failed_outages == 1
    finally:
        server.stop()


def test_an_asyncio_session_rides_through_a_server_restart(masses, reference):
    j_star = reference["masses_N30"]["closed_loop"]["J_star"]
    server = ServerProcess()

    async def run():
        async with nupmpc.aio.connect(server.target) as client:
            session = await client.session(masses.problem)
            for t, x in enumerate(masses.closed_loop_states[:30]):
                if t == 10:
                    server.restart()
                plan = await session.step(x)
                np.testing.assert_array_equal(plan.x[0], x)
                assert abs(plan.objective - j_star[t]) <= 1e-6 * abs(j_star[t]), t
            await session.close()
            return session.reconnects

    try:
        assert asyncio.run(run()) == 1
    finally:
        server.stop()
