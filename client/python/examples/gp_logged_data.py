"""GP-MPC from logged data: a nonlinear tank-like plant y[k] = 0.9 y[k-1] + 0.4 tanh(u[k])
+ noise (σ = 0.02) is excited with random inputs (the log), the GP's hyper-parameters are fitted by
the server (FitGpModel), and a GP session tracks a reference step from 0 to 0.6 within
|u| ≤ 1 and |Δu| ≤ 0.3, against the true plant. Writes gp_logged_data.png."""

import numpy as np

from _common import arguments

import nupmpc


def plant(y, u, rng):
    return 0.9 * y + 0.4 * np.tanh(u) + 0.02 * rng.standard_normal()


args = arguments(__doc__, steps=(40, "control periods"))
rng = np.random.default_rng(7)
logged_u = rng.uniform(-1, 1, 150)
logged_y = np.zeros(150)
for k in range(1, 150):
    logged_y[k] = plant(logged_y[k - 1], logged_u[k], rng)

with nupmpc.connect(args.server) as client:
    fit = client.fit_gp_model(nupmpc.problem.pb.GpModel(output_lags=1, input_lags=0, logged_outputs=logged_y,
                                                        logged_inputs=logged_u))
    print(f"GP fitted on {fit.num_points} pairs in {fit.fit_ms:.0f} ms, training RMSE {fit.training_rmse:.4f}")
    problem = nupmpc.GpProblem(logged_y, logged_u, output_lags=1, input_lags=0, horizon=10, output_weight=10.0,
                               input_change_weight=0.1, input_bounds=(-1, 1), rate_bounds=(-0.3, 0.3),
                               sigma_multiple=2.0, reference=0.0, kernel=fit.kernel)
    session = client.session(problem)
    # The session's state is the past window [y[t-1], u[t-1]]; the plant holds y and u.
    y, u = 0.0, 0.0

    def gp_plant(window, applied):
        global y, u
        y, u = plant(y, applied[0], rng), applied[0]
        return np.array([y, u])

    trajectory = nupmpc.simulate(session, plant=gp_plant, x0=[0.0, 0.0], steps=args.steps,
                                 step_args=lambda t, x: {"references": [0.6 if t >= 5 else 0.0]})

path = args.out / "gp_logged_data.png"
trajectory.plot(path, title="GP-MPC from logged data")
print(f"final output {trajectory.x[-1, 0]:.3f} (reference 0.6); figure: {path}")
