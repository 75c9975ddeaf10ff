"""Model updates (Step.model) against a real server: each kind of update gives the plan of a
session created with the equivalent time-varying spec; rejected updates change nothing;
nonlinear plants by real-time iteration (NonlinearSession); offset-free tracking with a
disturbance estimate sent as state offsets."""

import asyncio

import numpy as np
import pytest

import nupmpc
from nupmpc._proto import pb
from conftest import ServerProcess

# A damped chain of three states, two inputs (both bounded, active at the start), two outputs.
N, M, L, K = 12, 3, 2, 2
DT = 0.1
A0 = np.array([[1.0, DT, 0.0], [0.0, 1.0, DT], [0.0, -0.2, 0.9]])
B0 = np.array([[0.0, 0.0], [DT, 0.0], [0.1, 0.05]])
C0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
X = np.array([0.2, -0.1, 0.3])


def _chain(A=A0, B=B0, C=C0, state_offset=None, output_offset=None, x0=X):
    return (nupmpc.Problem(A, B, C, horizon=N, x0=x0, state_offset=state_offset, output_offset=output_offset)
            .output_weight([10.0, 1.0], reference=[1.0, 0.0]).input_weight(0.1).input_box(-0.6, 0.6)
            .options(objective_tolerance=1e-14))


def _per_step(matrix, steps):
    return np.stack([matrix] * steps)


def _relative(a, b):
    return np.abs(a - b).max() / max(1.0, np.abs(b).max())


def _assert_same_plan(plan, expected, what):
    assert plan.converged and expected.converged, (what, plan, expected)
    assert _relative(plan.u, expected.u) <= 1e-7, (what, _relative(plan.u, expected.u))
    assert _relative(plan.x, expected.x) <= 1e-7, (what, _relative(plan.x, expected.x))
    assert _relative(plan.y, expected.y) <= 1e-7, (what, _relative(plan.y, expected.y))


def _check(client, session, plan, expected_problem, x, what):
    """The session's plan is a fresh session's on the expected spec, solved cold on the same
    state, and the spec the session would be re-created from is that spec's model."""
    assert session.spec.model == expected_problem.spec.model, what
    fresh = client.session(expected_problem.initial_state(x))
    _assert_same_plan(plan, fresh.step(x, warm_start="cold"), what)
    fresh.close()


# (a) Each kind of update through Session.step.

def test_per_step_matrices_make_a_time_invariant_model_time_varying(client):
    rng = np.random.default_rng(3)
    session = client.session(_chain())
    assert session.step(X).converged
    A3 = A0 + 0.05 * rng.standard_normal((M, M))
    B5 = 1.5 * B0
    C_end = np.array([[1.0, 0.5, 0.0], [0.0, 0.0, 1.0]])
    x = X + 0.05
    plan = session.step(x, model=nupmpc.ModelUpdate(A={3: A3}, B={5: B5}, C={N: C_end}))
    A, B, C = _per_step(A0, N), _per_step(B0, N), _per_step(C0, N + 1)
    A[3], B[5], C[N] = A3, B5, C_end
    _check(client, session, plan, _chain(A, B, C), x, "A[3], B[5], C[N]")
    assert not plan.raw.warm_started  # the storage became per-step: the warm start restarts once
    # Now stored per step: later updates keep the warm start. A whole (N, M, M) array too.
    A = A + 0.01 * rng.standard_normal((N, M, M))
    plan = session.step(x, model=nupmpc.ModelUpdate(A=A, B={0: 0.5 * B0}))
    B[0] = 0.5 * B0
    _check(client, session, plan, _chain(A, B, C), x, "every A, B[0]")
    assert plan.raw.warm_started
    # One matrix: the same at every step (stored per step).
    plan = session.step(x, model=nupmpc.ModelUpdate(C=C0))
    _check(client, session, plan, _chain(A, B, _per_step(C0, N + 1)), x, "C at every step")
    session.close()


def test_all_step_offsets_every_form(client):
    rng = np.random.default_rng(4)
    session = client.session(_chain())
    session.step(X)
    c = np.array([0.01, -0.02, 0.03])
    plan = session.step(X, model=nupmpc.ModelUpdate(state_offset=c, output_offset=[0.1, -0.1]))
    _check(client, session, plan, _chain(state_offset=c, output_offset=[0.1, -0.1]), X, "constant offsets")
    c_steps = 0.02 * rng.standard_normal((N, M))
    d_steps = 0.05 * rng.standard_normal((N + 1, K))
    plan = session.step(X, model=nupmpc.ModelUpdate(state_offset=c_steps, output_offset=d_steps))
    _check(client, session, plan, _chain(state_offset=c_steps, output_offset=d_steps), X, "per-step offsets")
    # Single steps on top of per-step offsets; then constant ones again, which a session
    # keeps per step (the same value at every step), as does its spec.
    plan = session.step(X, model=nupmpc.ModelUpdate(state_offset={2: [0.1, 0.0, 0.0]}, output_offset={N: [0.0, 0.3]}))
    c_steps[2], d_steps[N] = [0.1, 0.0, 0.0], [0.0, 0.3]
    _check(client, session, plan, _chain(state_offset=c_steps, output_offset=d_steps), X, "offsets at single steps")
    plan = session.step(X, model=nupmpc.ModelUpdate(state_offset=c))
    _check(client, session, plan, _chain(state_offset=_per_step(c, N), output_offset=d_steps), X, "c again")
    assert len(session.spec.model.state_offset) == N * M
    session.close()


def test_output_offsets_move_the_outputs_and_their_tracking(client):
    session = client.session(_chain())
    plain = session.step(X, warm_start="cold")
    d = np.array([0.25, -0.1])
    plan = session.step(X, model=nupmpc.ModelUpdate(output_offset=d))
    _check(client, session, plan, _chain(output_offset=d), X, "output offsets")
    # The offset enters y[0] = C x[0] + d directly (x[0] is fixed): the measured y moves by d.
    np.testing.assert_allclose(plan.y[0] - plain.y[0], d, atol=1e-12)
    session.close()


def test_shift_moves_every_per_step_term_and_keeps_time_invariant_ones(client):
    rng = np.random.default_rng(5)
    A = A0 + 0.02 * rng.standard_normal((N, M, M))
    c = 0.02 * rng.standard_normal((N, M))
    d = 0.05 * rng.standard_normal((N + 1, K))
    session = client.session(_chain(A=A, state_offset=c, output_offset=d))  # B, C time-invariant
    session.step(X)
    x = np.array([0.1, 0.0, 0.2])
    A_new = A0 + 0.02 * rng.standard_normal((M, M))
    c_new = [0.0, 0.05, 0.0]
    plan = session.step(x, model=nupmpc.ModelUpdate(shift=True, A={N - 1: A_new}, state_offset={N - 1: c_new}))
    A_shifted, c_shifted = np.concatenate([A[1:], [A_new]]), np.concatenate([c[1:], [c_new]])
    d_shifted = np.concatenate([d[1:], d[-1:]])  # the last step repeated
    _check(client, session, plan, _chain(A=A_shifted, state_offset=c_shifted, output_offset=d_shifted), x, "shift")
    assert plan.raw.warm_started
    assert len(session.spec.model.b) == 1 and len(session.spec.model.c) == 1  # unchanged, not per-step
    # A shift alone: the last step repeated.
    plan = session.step(x, model=nupmpc.ModelUpdate(shift=True))
    expected = _chain(A=np.concatenate([A_shifted[1:], [A_new]]), state_offset=np.concatenate([c_shifted[1:], [c_new]]),
                      output_offset=np.concatenate([d_shifted[1:], d_shifted[-1:]]))
    _check(client, session, plan, expected, x, "shift alone")
    session.close()


def test_the_asyncio_session_takes_model_updates(server):
    c = np.array([0.01, -0.02, 0.03])

    async def run():
        async with nupmpc.aio.connect(server.target) as client:
            session = await client.session(_chain())
            await session.step(X)
            plan = await session.step(X, model=nupmpc.ModelUpdate(A={1: 0.9 * A0}, state_offset=c))
            spec = session.spec
            await session.close()
            return plan, spec

    plan, spec = asyncio.run(run())
    A = _per_step(A0, N)
    A[1] = 0.9 * A0
    assert spec.model == _chain(A=A, state_offset=c).spec.model
    with nupmpc.connect(server.target) as client:
        _assert_same_plan(plan, client.session(_chain(A=A, state_offset=c)).step(X, warm_start="cold"), "aio")


def test_model_updates_survive_a_server_restart():
    """The session re-created after a restart has the updated model (the spec mirror): its
    plans equal a twin's on a server that never went away."""
    rng = np.random.default_rng(6)
    restarted, steady = ServerProcess(), ServerProcess()
    try:
        with nupmpc.connect(restarted.target) as a, nupmpc.connect(steady.target) as b:
            sessions = [a.session(_chain()), b.session(_chain())]
            x = X.copy()
            for t in range(8):
                if t == 5:
                    restarted.restart()
                update = nupmpc.ModelUpdate(shift=True, A={N - 1: A0 + 0.02 * rng.standard_normal((M, M))},
                                            state_offset={t % N: 0.01 * rng.standard_normal(M)},
                                            output_offset=0.01 * rng.standard_normal(K))
                plan_a, plan_b = (s.step(x, model=update, warm_start="cold") for s in sessions)
                _assert_same_plan(plan_a, plan_b, f"step {t}")
                x = A0 @ x + B0 @ plan_b.u0
            assert sessions[0].reconnects == 1 and sessions[1].reconnects == 0
            assert sessions[0].spec == sessions[1].spec
    finally:
        restarted.stop()
        steady.stop()


# (b) Rejected updates.

def _raw(kind):
    """A pb.ModelUpdate with valid changes and one bad entry (sent unchecked)."""
    update = pb.ModelUpdate(state_offsets=[0.5, 0.5, 0.5])
    update.a.add(step=2, matrix=pb.Matrix(rows=M, cols=M, data=(2 * A0).ravel().tolist()))
    if kind == "shape":
        update.b.add(step=1, matrix=pb.Matrix(rows=M, cols=1, data=[1.0, 2.0, 3.0]))
    elif kind == "step":
        update.c.add(step=N + 1, matrix=pb.Matrix(rows=K, cols=M, data=C0.ravel().tolist()))
    else:
        update.state_offset.add(step=4, values=[0.0, float("inf"), 0.0])
    return update


@pytest.mark.parametrize("kind,field,text", [
    ("shape", "step.model.b[0].matrix", "expected 3x2, got 3x1"),
    ("step", "step.model.c[0].step", "must be < horizon + 1 = 13"),
    ("finite", "step.model.state_offset[0].values", "non-finite"),
])
def test_a_rejected_update_names_the_field_and_leaves_the_session_as_it_was(client, kind, field, text):
    session, twin = client.session(_chain()), client.session(_chain())
    for s in (session, twin):
        s.step(X)
    before = session.spec
    with pytest.raises(nupmpc.InvalidArgument) as caught:
        session.step(X + 0.3, model=_raw(kind), shift=True, references=[0.5, 0.0])
    assert caught.value.field == field, caught.value
    assert text in caught.value.details, caught.value
    assert session.spec == before and session.reconnects == 0
    # The next valid step gives exactly the plan of the twin that never saw the bad one.
    good = nupmpc.ModelUpdate(A={1: 0.95 * A0}, state_offset=[0.0, 0.01, 0.0])
    x = X + 0.1
    plan, expected = session.step(x, model=good), twin.step(x, model=good)
    assert plan.converged
    np.testing.assert_array_equal(plan.u, expected.u)
    np.testing.assert_array_equal(plan.x, expected.x)
    assert plan.iterations == expected.iterations and plan.raw.warm_started == expected.raw.warm_started
    assert session.spec == twin.spec
    session.close()
    twin.close()


def test_shapes_of_a_model_update_are_refused_before_anything_is_sent(client):
    session = client.session(_chain())
    session.step(X)
    before, spec = client.server_info(), session.spec
    cases = [
        (nupmpc.ModelUpdate(A={0: np.eye(2)}), "model.A[0]"),
        (nupmpc.ModelUpdate(B=np.zeros((N - 1, M, L))), "model.B"),
        (nupmpc.ModelUpdate(C={N + 1: C0}), "model.C"),
        (nupmpc.ModelUpdate(A={-1: A0}), "model.A"),
        (nupmpc.ModelUpdate(A={1.5: A0}), "model.A"),
        (nupmpc.ModelUpdate(A={2: np.where(np.eye(M) > 0, np.inf, 0.0)}), "model.A[2]"),
        (nupmpc.ModelUpdate(A=np.full((N, M, M), np.nan)), "model.A"),
        (nupmpc.ModelUpdate(state_offset=np.zeros(4)), "model.state_offset"),
        (nupmpc.ModelUpdate(state_offset=np.zeros((N + 1, M))), "model.state_offset"),
        (nupmpc.ModelUpdate(state_offset={N: np.zeros(M)}), "model.state_offset"),
        (nupmpc.ModelUpdate(state_offset={3: [0, np.inf, 0]}), "model.state_offset[3]"),
        (nupmpc.ModelUpdate(output_offset=np.zeros((N, K))), "model.output_offset"),
        ("A", "model"),
    ]
    for update, argument in cases:
        with pytest.raises(nupmpc.ShapeError) as caught:
            session.step(X + 1.0, model=update)
        assert caught.value.argument == argument, (argument, str(caught.value))
    # A session that takes no model update: refused here too (the server would refuse it).
    rate = client.session(_chain().input_rate(-0.1, 0.1))
    with pytest.raises(nupmpc.ShapeError) as caught:
        rate.step(X, model=nupmpc.ModelUpdate(state_offset=np.zeros(M)))
    assert caught.value.argument == "model"
    after = client.server_info()
    assert after.solves == before.solves and dict(after.errors_by_code) == dict(before.errors_by_code)
    assert session.spec == spec
    rate.close()
    session.close()


# (c) Nonlinear plants: NonlinearModel and NonlinearSession.

UDT = 0.1  # the unicycle's sample time


def unicycle(x, u):
    """Kinematic unicycle: position (p_x, p_y), heading θ; inputs speed v and turn rate ω."""
    return np.array([x[0] + UDT * u[0] * np.cos(x[2]), x[1] + UDT * u[0] * np.sin(x[2]), x[2] + UDT * u[1]])


def unicycle_x(x, u):
    return np.array([[1, 0, -UDT * u[0] * np.sin(x[2])], [0, 1, UDT * u[0] * np.cos(x[2])], [0, 0, 1]])


def unicycle_u(x, u):
    return np.array([[UDT * np.cos(x[2]), 0], [UDT * np.sin(x[2]), 0], [0, UDT]])


def position(x):
    return x[:2].copy()


def position_x(x):
    return np.eye(2, 3)


PDT, G = 0.05, 9.81  # the pendulum's sample time and g/l


def pendulum(x, u):
    """A pendulum about its upright position (θ = 0 up), torque input, explicit Euler."""
    return np.array([x[0] + PDT * x[1], x[1] + PDT * (G * np.sin(x[0]) - 0.2 * x[1] + u[0])])


def pendulum_x(x, u):
    return np.array([[1.0, PDT], [PDT * G * np.cos(x[0]), 1 - PDT * 0.2]])


def test_finite_difference_jacobians_agree_with_analytic_ones():
    rng = np.random.default_rng(7)
    analytic = nupmpc.NonlinearModel(unicycle, position, f_x=unicycle_x, f_u=unicycle_u, h_x=position_x)
    differences = nupmpc.NonlinearModel(unicycle, position)
    for _ in range(20):
        x, u = rng.uniform(-3, 3, 3), rng.uniform(-2, 2, 2)
        for given, estimated in zip(analytic.jacobians(x, u), differences.jacobians(x, u)):
            np.testing.assert_allclose(given, estimated, rtol=0, atol=1e-8)
    # The linearisation of a linear model is the model.
    linear = nupmpc.NonlinearModel(lambda x, u: A0 @ x + B0 @ u + 0.1, lambda x: C0 @ x - 0.2)
    xs, us = rng.standard_normal((N + 1, M)), rng.standard_normal((N, L))
    lin = linear.linearise(xs, us)
    np.testing.assert_allclose(lin.A, _per_step(A0, N), atol=1e-8)
    np.testing.assert_allclose(lin.B, _per_step(B0, N), atol=1e-8)
    np.testing.assert_allclose(lin.C, _per_step(C0, N + 1), atol=1e-8)
    np.testing.assert_allclose(lin.c, np.full((N, M), 0.1), atol=1e-8)
    np.testing.assert_allclose(lin.d, np.full((N + 1, K), -0.2), atol=1e-8)


def test_a_wrong_jacobian_is_refused_naming_it_and_its_entry(client):
    def wrong_x(x, u):  # the sign of ∂p_y/∂θ flipped
        J = unicycle_x(x, u)
        J[1, 2] = -J[1, 2]
        return J

    problem = nupmpc.NonlinearModel(unicycle, position).problem([0, 0, 0], [0.5, 0], horizon=10).input_weight(0.1)
    sessions = len(client.list_sessions())
    with pytest.raises(nupmpc.JacobianError) as caught:
        nupmpc.NonlinearSession(client, problem, nupmpc.NonlinearModel(unicycle, position, f_x=wrong_x),
                                u_guess=[0.5, 0.0])
    assert caught.value.argument == "f_x" and caught.value.entry == (1, 2), caught.value
    assert str(caught.value).startswith("f_x: entry [1, 2]")
    with pytest.raises(nupmpc.JacobianError) as caught:  # ∂θ/∂ω missing
        nupmpc.NonlinearSession(client, problem, nupmpc.NonlinearModel(
            unicycle, position, f_u=lambda x, u: unicycle_u(x, u) * [[1, 1], [1, 1], [1, 0]]))
    assert caught.value.argument == "f_u" and caught.value.entry == (2, 1), caught.value
    with pytest.raises(nupmpc.JacobianError) as caught:
        nupmpc.NonlinearSession(client, problem, nupmpc.NonlinearModel(unicycle, position,
                                                                        h_x=lambda x: np.eye(2, 3)[::-1]))
    assert caught.value.argument == "h_x", caught.value
    assert len(client.list_sessions()) <= sessions  # refused before any session was created


def test_rti_drives_a_unicycle_to_its_goal_within_the_input_bounds(client):
    """Real-time iteration: one linearisation and one solve per period. Speed |v| ≤ 0.5 and
    turn rate |ω| ≤ 0.5 (both saturate at first) from the origin, heading 0, to the goal
    (2, 1): ≥ 4.5 s at full speed, so 8 s (80 periods) leave about 3 s to settle."""
    goal = np.array([2.0, 1.0])
    model = nupmpc.NonlinearModel(unicycle, position, f_x=unicycle_x, f_u=unicycle_u, h_x=position_x)
    problem = (model.problem([0, 0, 0], [0.5, 0], horizon=50).output_weight(1.0, goal).input_weight(0.01)
               .input_box(-0.5, 0.5).terminal_cost(np.diag([50.0, 50.0, 0.0]), [*goal, 0]))
    with nupmpc.NonlinearSession(client, problem, model, u_guess=[0.5, 0.0]) as session:
        x, inputs = np.zeros(3), []
        for t in range(80):
            plan = session.step(x)
            assert plan.converged, (t, plan)
            np.testing.assert_array_equal(plan.x[0], x)
            inputs.append(plan.u0)
            x = unicycle(x, plan.u0)
        periods = session.periods
    assert np.abs(inputs).max() <= 0.5 + 1e-9  # the bounds hold on every applied input...
    assert np.isclose(np.abs(inputs).max(), 0.5)  # ...and were active
    # Settled: the position error is far below the distance travelled (2.24), and still
    # falling (the turn-rate-limited final approach).
    assert np.linalg.norm(x[:2] - goal) < 1e-3, x
    assert all(p.linearisations == 1 for p in periods)
    cold = periods[0].passes
    later = np.median([p.passes for p in periods[5:]])
    assert later <= 0.25 * cold, (cold, later, [p.passes for p in periods])


def test_rti_stabilises_a_pendulum_from_a_large_angle_with_a_saturated_torque(client):
    """From 1.5 rad off upright (gravity's torque there 9.8, the bound 12: the torque
    saturates while sin θ is far from its linearisation at the start), RTI with Jacobians
    partly by finite differences (f_u given; f_x and h_x estimated) brings it up in 4 s."""
    model = nupmpc.NonlinearModel(pendulum, lambda x: x[:1], f_u=lambda x, u: np.array([[0.0], [PDT]]))
    problem = (model.problem([1.5, 0.0], [0.0], horizon=40).output_weight(10.0, 0.0).input_weight(0.01)
               .input_box(-12, 12).terminal_cost(np.diag([100.0, 10.0])))
    with nupmpc.NonlinearSession(client, problem, model) as session:
        x, torques = np.array([1.5, 0.0]), []
        for t in range(80):
            plan = session.step(x)
            assert plan.converged, (t, plan)
            torques.append(plan.u0[0])
            x = pendulum(x, plan.u0)
    assert np.abs(torques).max() <= 12 + 1e-9 and np.isclose(np.abs(torques).max(), 12)
    # Up by period 30, then |x| falls about 10x per 10 periods (1e-6 at period 80): 1e-4
    # means settled upright, not merely near it.
    assert np.abs(x).max() < 1e-4, x


def test_sqp_iterations_converge_to_a_plan_of_the_nonlinear_model(client):
    """Up to 30 linearisations in one period: the plan stops moving, and then it satisfies
    the nonlinear dynamics (RTI's single linearisation does not)."""
    model = nupmpc.NonlinearModel(pendulum, lambda x: x[:1])
    problem = (model.problem([1.0, 0.0], [0.0], horizon=40).output_weight(10.0, 0.0).input_weight(0.01)
               .input_box(-12, 12).terminal_cost(np.diag([100.0, 10.0])))

    def defect(plan):
        return max(np.abs(plan.x[n + 1] - pendulum(plan.x[n], plan.u[n])).max() for n in range(40))

    x = np.array([1.0, 0.0])
    with nupmpc.NonlinearSession(client, problem, model, iterations=30, tolerance=1e-9) as session:
        rti = session.step(x, iterations=1)
        plan = session.step(x)
        period = session.periods[-1]
    assert 1 < period.linearisations < 30 and period.moved < 1e-9, period
    assert rti.converged and plan.converged
    assert defect(plan) < 1e-10 and defect(rti) > 1e-3, (defect(plan), defect(rti))
    assert np.abs(plan.u).max() <= 12 + 1e-9


# (d) Offset-free tracking: a disturbance estimate sent as state offsets.

def test_a_disturbance_estimate_as_state_offsets_removes_the_steady_state_error(client):
    """The plant's input gain is 1.3× the model's and a constant disturbance of -0.4 adds to
    its input. The client estimates d̂ ← d̂ + α·(x - (A x_prev + B u_prev + d̂)), sends it as
    the state offsets and steers to the steady state (x_s, u_s) of the model with d̂ and the
    reference as input reference (target calculation): the output settles on r exactly.
    Without the estimate (d̂ = 0, the same controller) an offset remains."""
    A = np.array([[0.9, 0.2], [0.0, 0.8]])
    B = np.array([[0.0], [0.5]])
    C = np.array([[1.0, 0.0]])
    B_true, w = 1.3 * B, (1.3 * B * -0.4).ravel()
    r, alpha = 1.0, 0.6
    problem = nupmpc.Problem(A, B, C, horizon=20).output_weight(1.0, r).input_weight(0.1).input_box(-3, 3)
    steady = np.block([[np.eye(2) - A, -B], [C, np.zeros((1, 1))]])

    def run(estimate):
        session = client.session(problem)
        x, d, previous, y = np.zeros(2), np.zeros(2), None, []
        for t in range(80):
            if estimate and previous is not None:
                d = d + alpha * (x - (A @ previous[0] + B @ previous[1] + d))
            u_s = np.linalg.solve(steady, np.r_[d, r])[2:]
            plan = session.step(x, input_references=u_s,
                                model=nupmpc.ModelUpdate(state_offset=d) if estimate else None)
            assert plan.converged, t
            previous = (x, plan.u0)
            x = A @ x + B_true @ plan.u0 + w
            y.append((C @ x)[0])
        session.close()
        return np.array(y)

    offset_free, plain = run(True), run(False)
    assert np.abs(offset_free[-20:] - r).max() < 1e-6, offset_free[-20:] - r
    assert np.abs(plain[-20:] - r).min() > 0.1, plain[-20:] - r
