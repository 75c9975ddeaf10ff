"""A server restart mid-loop is ridden through: SIGKILL the server, start a new one on
the same port, and the loop goes on; every step's plan is for the state sent."""

import asyncio

import numpy as np

import nupmpc
from conftest import ServerProcess


def test_a_session_rides_through_a_server_restart(masses, reference):
    j_star = reference["masses_N30"]["closed_loop"]["J_star"]
    server = ServerProcess()
    attempts = []

    def on_attempt(attempt):
        """The server comes back once an attempt was refused: the step is sent while it is down,
        however slow this machine."""
        attempts.append(attempt)
        if attempt.error is not None and server.process.poll() is not None:
            server.start()

    try:
        with nupmpc.connect(server.target) as client:
            session = client.session(masses.problem, nupmpc.ReconnectOptions(on_attempt=on_attempt, seed=1))
            first_id = session.id
            for t, x in enumerate(masses.closed_loop_states[:40]):
                if t == 15:
                    server.kill()
                plan = session.step(x)
                np.testing.assert_array_equal(plan.x[0], x)
                assert plan.converged, t
                assert abs(plan.objective - j_star[t]) <= 1e-6 * abs(j_star[t]), t
            assert session.reconnects == 1
            assert session.id != first_id  # re-created under a new id
            assert attempts[0].error is not None and attempts[-1].error is None  # refused while down, then back
            # Asked for by its id first: the restarted server (no state directory) does not
            # have it, so it was re-created from the spec.
            assert (session.stats.reattached, session.stats.recreated) == (0, 1)
            assert attempts[-1].path == "recreated" and attempts[-1].attach_by_id == "NOT_FOUND"
            assert attempts[0].path == "none" and attempts[0].attach_by_id == "UNAVAILABLE"
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
            return session.stats

    try:
        stats = asyncio.run(run())
        # Asked for by its id first (the restarted server does not have it), re-created.
        assert (stats.reconnects, stats.reattached, stats.recreated) == (1, 0, 1)
        assert stats.attempt_log[-1].path == "recreated" and stats.attempt_log[-1].attach_by_id == "NOT_FOUND"
    finally:
        server.stop()


def test_a_session_re_created_after_a_restart_is_the_session_the_server_had():
    """What the steps changed (shifted per-step references, a new bound, Δu's u[-1]) is in
    the re-created session: after the restart its plans equal those of a twin session on
    a server that never went away (the Python mirror of reconnect_fidelity_test)."""
    N = 15
    reference = np.sin(np.linspace(0, 3, N + 1))[:, None] * [1.0, 0.0]
    problem = (nupmpc.Problem([[1, 0.1], [0, 1]], [[0.005], [0.1]], np.eye(2), horizon=N, x0=[0, 0])
               .output_weight([10.0, 0.1], reference=reference).input_weight(0.01).input_box(-2, 2)
               .input_rate(-0.3, 0.3))
    restarted, steady = ServerProcess(), ServerProcess()
    try:
        with nupmpc.connect(restarted.target) as a, nupmpc.connect(steady.target) as b:
            sessions = [a.session(problem), b.session(problem)]
            x = np.array([0.2, 0.0])
            for t in range(14):
                if t == 9:
                    restarted.restart()
                kwargs = {"shift": True, "warm_start": "cold"}
                if t == 3:
                    kwargs["bounds"] = (None, [0.6, np.inf])
                if t == 6:
                    kwargs["references"] = np.c_[np.linspace(0.5, 1.0, N + 1), np.zeros(N + 1)]
                plan_a, plan_b = (s.step(x, **kwargs) for s in sessions)
                assert plan_a.objective == plan_b.objective or \
                    abs(plan_a.objective - plan_b.objective) <= 1e-9 * abs(plan_b.objective), t
                np.testing.assert_allclose(plan_a.u, plan_b.u, atol=1e-7, err_msg=f"step {t}")
                x = np.array([[1, 0.1], [0, 1]]) @ x + np.array([0.005, 0.1]) * plan_b.u0[0]
            assert sessions[0].reconnects == 1 and sessions[1].reconnects == 0
            assert sessions[0].spec == sessions[1].spec
    finally:
        restarted.stop()
        steady.stop()
