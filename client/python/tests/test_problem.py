"""The Problem builder: specs the server accepts and solves as asked, the JSON round trip
(also through the C++ CLI), and the GP, keep-out, Δu and level features."""

import json
import os
import subprocess

import numpy as np
import pytest

import nupmpc
from conftest import CLI_BINARY


def _double_integrator(N=20):
    return (nupmpc.Problem([[1, 0.1], [0, 1]], [[0.005], [0.1]], [[1, 0], [0, 1]], horizon=N, x0=[1.0, 0.0])
            .input_box(-1, 1).input_weight(0.1).output_weight([10.0, 0.0]).terminal_cost(np.eye(2) * 5))


def test_json_round_trips_and_the_cli_solves_our_file_to_the_same_objective(client, server, tmp_path):
    problem = _double_integrator().output_box(lower=[-0.2, -2], soft=100.0)
    text = problem.to_json()
    again = nupmpc.Problem.from_json(text)
    assert again.spec == problem.spec
    path = tmp_path / "spec.json"
    path.write_text(text)
    assert nupmpc.load_instance(path).spec == problem.spec
    ours = client.solve_once(problem)
    assert ours.converged
    if not os.access(CLI_BINARY, os.X_OK):
        pytest.fail(f"no CLI binary at {CLI_BINARY}")
    out = subprocess.run([CLI_BINARY, "--server", server.target, "--format", "json", "solve", str(path)],
                         capture_output=True, text=True, check=True).stdout
    assert json.loads(out)["objective"] == pytest.approx(ours.objective, rel=1e-12)


def test_the_builder_writes_the_spec_the_proto_describes():
    spec = (_double_integrator(N=4).output_box(upper=[0.5, np.inf]).input_box(lower=[[-1], [-1], [-0.5], [-0.5]],
                                                                                upper=1, soft=50.0).spec)
    u = spec.input_priors[0]
    assert u.kind == nupmpc.problem.pb.PRIOR_KIND_BOX
    assert list(u.lower) == [-1, -1, -0.5, -0.5] and list(u.upper) == [1] and list(u.slope) == [50]
    assert list(u.weight) == [0.1] and list(u.target) == [0]
    y = spec.output_priors[0]
    assert y.kind == nupmpc.problem.pb.PRIOR_KIND_AT_MOST and list(y.upper) == [0.5] and not y.lower
    assert list(spec.terminal.weight.data) == [5, 0, 0, 5]
    assert spec.model.a[0].rows == 2 and list(spec.model.b[0].data) == [0.005, 0.1]


def test_input_rate_limits_hold_in_the_plan(client):
    problem = _double_integrator().input_rate(-0.1, 0.1, previous_input=[0.0])
    session = client.session(problem)
    plan = session.step([1.0, 0.0])
    assert plan.has_plan
    du = np.diff(np.r_[0.0, plan.u[:, 0]])
    assert np.abs(du).max() <= 0.1 + 1e-7
    second = session.step([0.99, -0.05])
    assert abs(second.u[0, 0] - plan.u0[0]) <= 0.1 + 1e-7  # u[-1] carried from the last plan
    assert list(session.spec.input_differences.previous_input) == [second.u0[0]]
    session.close()


def test_input_levels_make_the_plan_discrete(client):
    # A multi-level input takes no prior of its own: the costs go on the outputs.
    problem = (nupmpc.Problem([[1, 0.1], [0, 1]], [[0.005], [0.1]], [[1, 0], [0, 1]], horizon=20, x0=[1.0, 0.0])
               .output_weight([10.0, 0.1]).input_levels(0, count=3, lowest=-1, spacing=1))
    plan = client.solve_once(problem)
    assert plan.has_plan
    assert set(np.round(plan.u[:, 0], 9)) <= {-1.0, 0.0, 1.0}


def test_a_keep_out_region_is_kept_out_of(client):
    # A point mass in the plane (x, y, vx, vy) from (0, 0) to (3, 3) around a disc at (1.5, 1.5).
    dt = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    B = np.array([[dt * dt / 2, 0], [0, dt * dt / 2], [dt, 0], [0, dt]])
    C = np.eye(2, 4)
    problem = (nupmpc.Problem(A, B, C, horizon=40, x0=[0, 0, 0, 0]).output_weight(1.0, reference=[3, 3])
               .input_weight(0.01).input_box(-5, 5).terminal_cost(np.eye(4) * 100, target=[3, 3, 0, 0])
               .keep_out(0, 1, [nupmpc.Ellipse(centre=(1.5, 1.2), a=0.5)]))
    plan = client.solve_once(problem)
    assert plan.converged and plan.linearisations >= 1
    distance = np.hypot(plan.y[1:, 0] - 1.5, plan.y[1:, 1] - 1.2)
    assert distance.min() >= 0.5 - 1e-6
    assert np.hypot(*(plan.y[-1] - 3)) < 0.3


def test_a_gp_session_from_logged_data(client):
    rng = np.random.default_rng(3)
    u = rng.uniform(-1, 1, 120)
    y = np.zeros(120)
    for k in range(1, 120):  # a first-order plant, y[k] = 0.8 y[k-1] + 0.5 u[k] + noise
        y[k] = 0.8 * y[k - 1] + 0.5 * u[k] + 0.01 * rng.standard_normal()
    fit = client.fit_gp_model(nupmpc.problem.pb.GpModel(output_lags=1, input_lags=0, logged_outputs=y,
                                                        logged_inputs=u))
    problem = nupmpc.GpProblem(y, u, output_lags=1, input_lags=0, horizon=8, input_bounds=(-1, 1),
                               rate_bounds=(-0.5, 0.5), reference=1.0, kernel=fit.kernel)
    session = client.session(problem)
    assert session.dims == (2, 1, 1, 8)
    plan = session.step([0.0, 0.0])
    assert plan.has_plan and plan.u.shape == (8, 1) and plan.output_stddev.shape == (9, 1)
    assert plan.y[-1, 0] > 0.5  # heading for the reference
    plan = session.step([0.2, plan.u0[0]], references=[0.5])
    assert list(session.spec.gp.reference) == [0.5]
    with pytest.raises(nupmpc.ShapeError) as caught:
        session.step([0.0, 0.0], references=np.zeros(3))
    assert caught.value.argument == "references"
    session.close()
