"""A point mass in the plane (position and velocity in x and y, accelerations as inputs)
goes from (0, 0) to (4, 3) around two keep-out regions (a disc and a rotated rectangle),
in a closed loop: every plan keeps out of the regions. Writes obstacle_avoidance.png (the
path in the plane) and obstacle_avoidance_loop.png (the trajectory panels)."""

import numpy as np

from _common import arguments

import nupmpc

args = arguments(__doc__, steps=(60, "control periods"))
dt = 0.1
A = np.eye(4)
A[0, 2] = A[1, 3] = dt
B = np.array([[dt * dt / 2, 0], [0, dt * dt / 2], [dt, 0], [0, dt]])
C = np.eye(2, 4)  # outputs: the position
goal = np.array([4.0, 3.0])
regions = [nupmpc.Ellipse(centre=(1.5, 1.0), a=0.6),
           nupmpc.Rectangle(centre=(2.6, 2.5), a=0.4, b=0.25, rotation=0.5)]
problem = (nupmpc.Problem(A, B, C, horizon=40, x0=[0, 0, 0, 0])
           .output_weight(1.0, reference=goal).input_weight(0.05).input_box(-3, 3)
           .terminal_cost(np.eye(4) * 50, target=[*goal, 0, 0])
           .keep_out(0, 1, regions))

with nupmpc.connect(args.server) as client:
    session = client.session(problem)
    trajectory = nupmpc.simulate(session, steps=args.steps)

trajectory.plot(args.out / "obstacle_avoidance_loop.png", title="point mass around two regions")

from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle, Rectangle as Box  # noqa: E402

fig = Figure(figsize=(6, 5), layout="constrained")
FigureCanvasAgg(fig)
ax = fig.subplots()
ax.set_title("Path in the plane")
ax.add_patch(Circle((1.5, 1.0), 0.6, color="0.7", label="keep-out disc"))
box = Box((2.6 - 0.4, 2.5 - 0.25), 0.8, 0.5, angle=np.degrees(0.5), rotation_point="center", color="0.5",
          label="keep-out rectangle")
ax.add_patch(box)
ax.plot(trajectory.x[:, 0], trajectory.x[:, 1], "o-", markersize=3, label="closed loop")
ax.plot(*goal, "k*", markersize=12, label="goal")
ax.set_aspect("equal")
ax.legend(loc="lower right", fontsize="small")
path = args.out / "obstacle_avoidance.png"
fig.savefig(path, dpi=90)
statuses = {s: trajectory.status.count(s) for s in sorted(set(trajectory.status))}
print(f"{trajectory.steps} steps, final position {np.round(trajectory.x[-1, :2], 3)}, statuses {statuses}")
print(f"figures: {path}, {args.out / 'obstacle_avoidance_loop.png'}")
