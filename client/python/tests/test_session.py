"""Sessions against a real server: the masses closed loop at the reference optima, updates
of references and bounds, typed server errors, the asyncio variant."""

import asyncio
import dataclasses

import numpy as np
import pytest

import nupmpc
from nupmpc._proto import pb


def test_masses_closed_loop_reaches_the_reference_optimum_at_every_step(client, masses, reference):
    j_star = reference["masses_N30"]["closed_loop"]["J_star"]
    states = masses.closed_loop_states
    assert len(states) == len(j_star) == 100
    session = client.session(masses.problem)
    M, L, K, N = session.dims
    for t, x in enumerate(states):
        plan = session.step(x)
        assert plan.status == "CONVERGED", t
        assert abs(plan.objective - j_star[t]) <= 1e-6 * abs(j_star[t]), (t, plan.objective, j_star[t])
        assert plan.u.shape == (N, L) and plan.x.shape == (N + 1, M) and plan.y.shape == (N + 1, K)
        np.testing.assert_array_equal(plan.x[0], x)  # the plan is for the state sent
        np.testing.assert_array_equal(plan.u0, plan.u[0])
        assert np.all(np.abs(plan.u) <= 0.5 + 1e-9)
        if t > 0:
            assert plan.raw.warm_started
    session.close()


def test_a_reference_and_a_bound_sent_with_a_step_change_the_plan_and_stay(client, masses):
    session = client.session(masses.problem)
    x = masses.closed_loop_states[0]
    free = session.step(x, warm_start="cold")
    # Output 0 to 1.0 everywhere: the plan moves towards it, and the spec the session would
    # be re-created from carries it (the server keeps an update for later steps).
    toward = session.step(x, references=np.r_[1.0, np.zeros(11)], warm_start="cold")
    assert np.abs(toward.y[1:, 0] - 1.0).mean() < np.abs(free.y[1:, 0] - 1.0).mean()
    expected = masses.problem.references(np.r_[1.0, np.zeros(11)]).initial_state(x)
    assert toward.objective == pytest.approx(client.solve_once(expected).objective, rel=1e-9)
    assert abs(toward.objective - free.objective) > 0.01 * free.objective
    assert list(session.spec.output_priors[0].target) == [1.0]
    again = session.step(x, warm_start="cold")
    assert again.objective == pytest.approx(toward.objective, rel=1e-9)
    # A tighter upper bound on output 0 (y ≤ 0.3 from step 15 on) holds in the plan.
    upper = np.full((31, 12), 4.0)
    upper[15:, 0] = 0.3
    bounded = session.step(x, bounds=(None, upper), warm_start="cold")
    assert bounded.converged, bounded
    assert bounded.y[15:, 0].max() <= 0.3 + 1e-7
    assert toward.y[15:, 0].max() > 0.4
    session.close()


def test_a_server_error_is_a_typed_exception_naming_the_field(client, masses):
    spec = masses.spec
    spec.input_priors[1].lower[0] = 1.0  # lower 1 > upper 0.5
    with pytest.raises(nupmpc.InvalidArgument) as caught:
        client.solve_once(spec)
    assert caught.value.code.name == "INVALID_ARGUMENT"
    assert caught.value.field is not None and caught.value.field.startswith("spec.input_priors[1]"), caught.value
    with pytest.raises(nupmpc.InvalidArgument) as caught:
        client.session(spec)
    assert caught.value.field is not None and "input_priors[1]" in caught.value.field, caught.value


def test_a_rejected_step_is_typed_and_the_stream_stays_open(client, masses):
    session = client.session(masses.problem)
    x = masses.closed_loop_states[0]
    # Output bounds crossing (lower > upper) are the server's to refuse: shapes are fine.
    with pytest.raises(nupmpc.InvalidArgument) as caught:
        session.step(x, bounds=(np.full(12, 1.0), np.full(12, -1.0)))
    assert caught.value.field is not None and "outputs" in caught.value.field, caught.value
    assert session.reconnects == 0
    assert session.step(x).converged  # same stream, same session
    assert session.reconnects == 0
    session.close()


def test_shapes_are_refused_before_anything_is_sent(client, masses):
    before = client.server_info()
    session = client.session(masses.problem)
    cases = [
        (lambda: session.step(np.zeros(11)), "x"),
        (lambda: session.step(np.zeros(12), references=np.zeros(5)), "references"),
        (lambda: session.step(np.zeros(12), bounds=(np.zeros((3, 12)), None)), "bounds.lower"),
        (lambda: session.step(np.zeros(12), input_bounds=(None, np.zeros(4))), "input_bounds.upper"),
        (lambda: session.step(np.full(12, np.nan)), "x"),
        (lambda: nupmpc.Problem(np.eye(3), np.ones((2, 1)), horizon=5), "B"),
        (lambda: nupmpc.Problem(np.eye(3), np.ones((3, 1)), np.ones((1, 2)), horizon=5), "C"),
        (lambda: nupmpc.Problem(np.ones((3, 2)), np.ones((3, 1)), horizon=5), "A"),
        (lambda: nupmpc.Problem(np.eye(3), np.ones((3, 1)), horizon=0), "horizon"),
        (lambda: nupmpc.Problem(np.eye(2), np.ones((2, 1)), horizon=4).input_box(-1, np.ones(3)), "input_box.upper"),
        (lambda: nupmpc.Problem(np.eye(2), np.ones((2, 1)), np.eye(2), horizon=4)
         .output_weight(1.0, reference=np.zeros((4, 2))), "output_weight.reference"),
        (lambda: nupmpc.Problem(np.eye(2), np.ones((2, 1)), horizon=4).terminal_cost(np.eye(3)), "terminal_cost.weight"),
    ]
    for call, argument in cases:
        with pytest.raises(nupmpc.ShapeError) as caught:
            call()
        assert caught.value.argument == argument, (argument, str(caught.value))
        assert str(caught.value).startswith(argument + ":")
    after = client.server_info()
    assert after.solves == before.solves  # nothing reached a solver
    assert dict(after.errors_by_code) == dict(before.errors_by_code)  # and nothing was refused there
    session.close()


def test_step_options_are_keyword_only_and_a_plan_is_frozen_with_a_string_status(client, masses):
    before = client.server_info()
    session = client.session(masses.problem)
    x = masses.closed_loop_states[0]
    with pytest.raises(TypeError):
        session.step(x, np.zeros(12))  # references by position
    assert client.server_info().solves == before.solves  # refused before anything was sent
    plan = session.step(x)
    assert plan.status is nupmpc.PlanStatus.CONVERGED and plan.status == "CONVERGED"
    assert str(plan.status) == f"{plan.status}" == "CONVERGED" and repr([plan.status]) == "['CONVERGED']"
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.status = nupmpc.PlanStatus.HELD
    session.close()


def test_plan_status_has_a_member_for_every_solve_status():
    names = {name.replace("SOLVE_STATUS_", "") for name in pb.SolveStatus.keys()}
    assert {status.value for status in nupmpc.PlanStatus} == names


def test_the_asyncio_session_gives_the_blocking_sessions_plans(server, masses, reference):
    j_star = reference["masses_N30"]["closed_loop"]["J_star"]

    async def run():
        async with nupmpc.aio.connect(server.target) as client:
            once = await client.solve_once(masses.spec)
            sessions = [await client.session(masses.problem) for _ in range(2)]
            objectives = []
            for t, x in enumerate(masses.closed_loop_states[:20]):
                # Two sessions stepped concurrently on one event loop.
                plans = await asyncio.gather(*(s.step(x) for s in sessions))
                objectives.append([p.objective for p in plans])
                for p in plans:
                    np.testing.assert_array_equal(p.x[0], x)
            for s in sessions:
                await s.close()
            return once, objectives

    once, objectives = asyncio.run(run())
    assert once.objective == pytest.approx(j_star[0], rel=1e-6)
    for t, pair in enumerate(objectives):
        for objective in pair:
            assert abs(objective - j_star[t]) <= 1e-6 * abs(j_star[t]), t
