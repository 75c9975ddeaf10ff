"""Six masses on springs (benchmarks/masses_N30.json): 100 control periods of a
closed loop against the session's own linear model with a push on the first mass at
t = 30; writes masses_closed_loop.png (states, outputs with |y| ≤ 4, inputs with |u| ≤ 0.5,
solve and round-trip times)."""

import numpy as np

from _common import BENCHMARKS, arguments

import nupmpc

args = arguments(__doc__, steps=(100, "control periods"))
instance = nupmpc.load_instance(BENCHMARKS / "masses_N30.json")
push = np.zeros((args.steps, 12))
push[min(30, args.steps - 1), 6:9] = 0.5  # velocities of the first three masses

with nupmpc.connect(args.server) as client:
    session = client.session(instance.problem)
    trajectory = nupmpc.simulate(session, x0=instance.closed_loop_states[0], steps=args.steps, disturbance=push)

path = args.out / "masses_closed_loop.png"
trajectory.plot(path, title="masses_N30: 6 masses, |u| ≤ 0.5, horizon 30")
print(f"{trajectory.steps} steps, all converged: {all(s == 'CONVERGED' for s in trajectory.status)}; "
      f"solve p50 {np.median(trajectory.solve_ms):.3f} ms, round trip p50 {np.median(trajectory.round_trip_ms):.3f} ms")
print(f"figure: {path}")
