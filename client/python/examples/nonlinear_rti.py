"""A kinematic unicycle (position and heading; speed and turn rate bounded by 0.5) driven
from the origin, heading 0, to the point (2, 1) by real-time iteration
(nupmpc.NonlinearSession): each period one linearisation along the previous plan shifted by
one step, sent with the measured state as one step (the whole time-varying model), warm
started. The same closed loop with every solve cold, for comparison. Prints the solver
passes and times per period of both, a summary of an SQP-style loop (up to 10
linearisations per period) and writes nonlinear_rti.png (the RTI closed loop)."""

import numpy as np

from _common import arguments

import nupmpc

args = arguments(__doc__, steps=(80, "control periods"), every=(5, "print every this many periods"))
dt = 0.1
goal = np.array([2.0, 1.0])


def unicycle(x, u):
    return np.array([x[0] + dt * u[0] * np.cos(x[2]), x[1] + dt * u[0] * np.sin(x[2]), x[2] + dt * u[1]])


def unicycle_x(x, u):
    return np.array([[1, 0, -dt * u[0] * np.sin(x[2])], [0, 1, dt * u[0] * np.cos(x[2])], [0, 0, 1]])


def unicycle_u(x, u):
    return np.array([[dt * np.cos(x[2]), 0], [dt * np.sin(x[2]), 0], [0, dt]])


model = nupmpc.NonlinearModel(unicycle, h=lambda x: x[:2], f_x=unicycle_x, f_u=unicycle_u,
                              h_x=lambda x: np.eye(2, 3))
problem = (model.problem(x0=[0, 0, 0], u0=[0.5, 0], horizon=50).output_weight(1.0, goal).input_weight(0.01)
           .input_box(-0.5, 0.5).terminal_cost(np.diag([50.0, 50.0, 0.0]), [*goal, 0]))

with nupmpc.connect(args.server) as client:
    rti = nupmpc.NonlinearSession(client, problem, model, u_guess=[0.5, 0])
    cold = nupmpc.NonlinearSession(client, problem, model, u_guess=[0.5, 0])
    trajectory = nupmpc.simulate(rti, plant=unicycle, steps=args.steps)
    # The cold loop sees the RTI loop's states (the two loops' plans agree to the solver's
    # tolerance: the comparison is of the same problems).
    for x in trajectory.x[:-1]:
        cold.step(x, warm_start="cold")
    # Up to 10 linearisations per period (SQP-style), in a closed loop of its own.
    sqp = nupmpc.NonlinearSession(client, problem, model, u_guess=[0.5, 0], iterations=10, tolerance=1e-8)
    sqp_loop = nupmpc.simulate(sqp, plant=unicycle, steps=args.steps)
    for session in (rti, cold, sqp):
        session.close()

print(f"{'period':>6} {'RTI passes':>11} {'RTI ms':>8} {'cold passes':>12} {'cold ms':>8}")
for t, (warm, fresh) in enumerate(zip(rti.periods, cold.periods)):
    if t < 3 or t % args.every == 0 or t == args.steps - 1:
        print(f"{t:>6} {warm.passes:>11} {warm.time_ms:>8.2f} {fresh.passes:>12} {fresh.time_ms:>8.2f}")
later = slice(5, None)
for name, periods in (("RTI (warm)", rti.periods), ("cold", cold.periods)):
    print(f"{name:<11} passes: first {periods[0].passes}, median after period 5 "
          f"{np.median([p.passes for p in periods[later]]):g}, total {sum(p.passes for p in periods)}; "
          f"time per period p50 {np.median([p.time_ms for p in periods]):.2f} ms "
          f"(solver {np.median([p.solve_ms for p in periods]):.3f} ms)")
print(f"SQP (≤ 10)  linearisations {sum(p.linearisations for p in sqp.periods)}, "
      f"passes {sum(p.passes for p in sqp.periods)}; "
      f"turn-rate variation Σ|Δω| {np.abs(np.diff(sqp_loop.u[:, 1])).sum():.2f} vs RTI's "
      f"{np.abs(np.diff(trajectory.u[:, 1])).sum():.2f} (one linearisation per period chatters while turning)")
print(f"final position {np.round(trajectory.x[-1, :2], 6)}, error {np.linalg.norm(trajectory.x[-1, :2] - goal):.2e}; "
      f"largest |u| {np.abs(trajectory.u).max(axis=0)}")
path = args.out / "nonlinear_rti.png"
trajectory.plot(path, title="unicycle to (2, 1) by RTI, |v|, |ω| ≤ 0.5, horizon 50")
print(f"figure: {path}")
