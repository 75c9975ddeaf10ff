"""nupmpc.simulate and Trajectory.plot: a closed loop against the session's linear model,
and a PNG whose panels hold what they should (the figure's axes, not its pixels)."""

import numpy as np

import nupmpc


def test_simulate_runs_the_closed_loop_on_the_linear_plant(client, masses):
    session = client.session(masses.problem)
    x0 = masses.closed_loop_states[0]
    w = np.zeros((25, 12))
    w[10, 0] = 0.3  # one push on the first mass
    trajectory = nupmpc.simulate(session, x0=x0, steps=25, disturbance=w)
    assert trajectory.x.shape == (26, 12) and trajectory.u.shape == (25, 3) and trajectory.y.shape == (25, 12)
    assert all(s == "CONVERGED" for s in trajectory.status)
    spec = masses.spec
    A = np.asarray(spec.model.a[0].data).reshape(12, 12)
    B = np.asarray(spec.model.b[0].data).reshape(12, 3)
    for t in range(25):  # the plant the helper simulated, step by step
        np.testing.assert_allclose(trajectory.x[t + 1], A @ trajectory.x[t] + B @ trajectory.u[t] + w[t], atol=1e-12)
        np.testing.assert_array_equal(trajectory.plans[t].x[0], trajectory.x[t])
    assert np.abs(trajectory.u).max() <= 0.5 + 1e-9
    assert np.linalg.norm(trajectory.x[-1]) < np.linalg.norm(trajectory.x[0])  # regulated towards 0
    session.close()


def test_plot_writes_a_png_with_states_outputs_inputs_and_times(client, masses, figure_dir):
    session = client.session(masses.problem)
    trajectory = nupmpc.simulate(session, x0=masses.closed_loop_states[0], steps=12)
    path = figure_dir / "masses.png"
    fig = trajectory.plot(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == ["States", "Outputs", "Inputs", "Solve and round-trip time"]
    states, outputs, inputs, times = fig.axes

    def lines(ax):
        return {line.get_label(): line for line in ax.get_lines()}

    assert [f"x{m}" for m in range(12)] == [label for label in lines(states)]
    np.testing.assert_array_equal(lines(states)["x3"].get_ydata(), trajectory.x[:, 3])
    out = lines(outputs)
    assert {"y ≤ 4", "y ≥ -4"} <= set(out) and {f"y{k}" for k in range(12)} <= set(out)
    np.testing.assert_array_equal(out["y ≤ 4"].get_ydata(), [4, 4])
    np.testing.assert_array_equal(out["y0"].get_ydata(), trajectory.y[:, 0])
    inp = lines(inputs)
    assert {"u0", "u1", "u2", "u ≤ 0.5", "u ≥ -0.5"} == set(inp)
    np.testing.assert_array_equal(inp["u2"].get_ydata(), trajectory.u[:, 2])
    tim = lines(times)
    assert set(tim) == {"solve (server)", "round trip (client)"}
    np.testing.assert_array_equal(tim["solve (server)"].get_ydata(), trajectory.solve_ms)
    assert (np.asarray(tim["round trip (client)"].get_ydata()) >= trajectory.solve_ms).all()
    session.close()


def test_references_are_drawn_when_the_outputs_have_them(client):
    # A double integrator tracking position 1: its reference line is in the Outputs panel.
    problem = (nupmpc.Problem([[1, 0.1], [0, 1]], [[0.005], [0.1]], [[1, 0]], horizon=20, x0=[0, 0])
               .output_weight(10.0, reference=1.0).input_weight(0.1).input_box(-1, 1).output_box(-0.5, 1.2))
    session = client.session(problem)
    trajectory = nupmpc.simulate(session, steps=30)
    fig = trajectory.plot()
    out = {line.get_label(): line for line in fig.axes[1].get_lines()}
    np.testing.assert_array_equal(out["y0 reference"].get_ydata(), np.ones(30))
    assert {"y ≤ 1.2", "y ≥ -0.5"} <= set(out)
    assert abs(trajectory.x[-1, 0] - 1.0) < 0.05  # it got there
    session.close()
