"""Closed loop against a Python plant: nupmpc.simulate(session, plant, x0, steps) runs
the session on the plant's states and collects a Trajectory (plot it with .plot())."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, Union

import numpy as np
import numpy.typing as npt

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, FloatArray
from nupmpc.result import Plan, PlanStatus
from nupmpc.spec_builder import from_spec

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from nupmpc.nonlinear import NonlinearSession
    from nupmpc.session import Session

# A plant: (x, u) → next x; a disturbance: an array (steps, M) or a callable t → w.
Plant = Callable[[FloatArray, FloatArray], ArrayLike]
Disturbance = Union[ArrayLike, Callable[[int], ArrayLike]]


def linear_plant(spec: pb.ProblemSpec) -> Plant:
    """x[t+1] = A x[t] + B u[t] + c from the spec's model (its first matrices)."""
    if spec.HasField("gp"):
        raise ValueError("plant: a GP session has no model to simulate; pass plant=callable(x, u)")
    m = spec.model
    M, L = m.num_states, m.num_inputs
    A = np.asarray(m.a[0].data).reshape(M, M)
    B = np.asarray(m.b[0].data).reshape(M, L)
    c = np.asarray(m.state_offset[:M]) if len(m.state_offset) else np.zeros(M)

    def plant(x: FloatArray, u: FloatArray) -> FloatArray:
        x_next: FloatArray = A @ x + B @ u + c
        return x_next
    return plant


def _disturbance(disturbance: Disturbance | None, steps: int, M: int) -> Callable[[int], FloatArray]:
    if disturbance is None:
        return lambda t: np.zeros(M)
    if callable(disturbance):
        given = disturbance  # narrowed here, not in the closure
        return lambda t: np.asarray(given(t), dtype=float)
    w = np.asarray(disturbance, dtype=float)
    if w.shape != (steps, M):
        from nupmpc.errors import ShapeError
        raise ShapeError("disturbance", f"expected shape ({steps}, {M}) or a callable t → w, got {w.shape}")

    def row(t: int) -> FloatArray:
        w_t: FloatArray = w[t]
        return w_t
    return row


@dataclass
class Trajectory:
    """A closed loop: x (T+1, M) the plant's states, u (T, L) the applied inputs, y (T, K)
    the outputs of each step's plan at its own state (y[0]), references (T, K) the output
    references in force (NaN: none), per-step status, objective, iterations, solve_ms and
    round_trip_ms, and the plans themselves. input_bounds/output_bounds: (lower, upper)."""
    x: FloatArray
    u: FloatArray
    y: FloatArray
    references: FloatArray
    status: list[PlanStatus]
    objective: FloatArray
    iterations: npt.NDArray[np.int_]
    solve_ms: FloatArray
    round_trip_ms: FloatArray
    has_plan: npt.NDArray[np.bool_]
    input_bounds: tuple[FloatArray, FloatArray]
    output_bounds: tuple[FloatArray, FloatArray]
    plans: list[Plan] = field(repr=False, default_factory=list)

    @property
    def steps(self) -> int:
        return len(self.u)

    def plot(self, path: str | os.PathLike[str] | None = None, title: str | None = None) -> Figure:
        """A matplotlib Figure: states, outputs with bounds and references, inputs with
        limits, solve and round-trip times per step; written to `path` (PNG) if given."""
        from nupmpc.plot import plot_trajectory
        return plot_trajectory(self, path, title)


def simulate(session: Session | NonlinearSession, plant: Plant | None = None, x0: ArrayLike | None = None,
             steps: int = 50, disturbance: Disturbance | None = None,
             step_args: Callable[[int, FloatArray], Mapping[str, Any]] | None = None) -> Trajectory:
    """Runs `steps` control periods: each sends the plant's state to the session, applies
    the plan's u0 (holding the last input when a result has no plan), and advances the
    plant, x ← plant(x, u) + w[t]. plant: None (the session's linear model) or a callable
    (x, u) → next x; x0: the initial state (default: the spec's); disturbance: None, an
    array (steps, M) or a callable t → w; step_args: a callable (t, x) → keyword arguments
    of session.step (references, bounds, ...) for that period."""
    spec = session.spec
    M, L, K, _ = session.dims
    plant = plant or linear_plant(spec)
    w = _disturbance(disturbance, steps, M)
    x = np.asarray(spec.initial_state.mean if x0 is None else x0, dtype=float)
    xs, us, ys, refs, plans = [x.copy()], [], [], [], []
    u = np.zeros(L)
    for t in range(steps):
        extra = step_args(t, x) if step_args else {}
        plan = session.step(x, **extra)
        plans.append(plan)
        # The references of the plan's first output step (GP sessions: y[0] is measured and
        # has none; their first reference is at step 1).
        in_force = from_spec(session.spec).output_references()
        refs.append(in_force[0] if np.isfinite(in_force[0]).any() or len(in_force) == 1 else in_force[1])
        if plan.u0 is not None:  # has_plan
            u = plan.u0
            ys.append(plan.y[0])
        else:
            ys.append(np.full(K, np.nan))
        us.append(u.copy())
        x = np.asarray(plant(x, u), dtype=float) + w(t)
        xs.append(x.copy())
    problem = from_spec(spec)
    in_lo, in_hi = problem.bounds("input")
    out_lo, out_hi = problem.bounds("output")
    row = 1 if out_lo.shape[0] > 1 else 0  # y[0] is measured: its bounds may be absent
    return Trajectory(
        x=np.array(xs), u=np.array(us).reshape(steps, L), y=np.array(ys).reshape(steps, K),
        references=np.array(refs).reshape(steps, K), status=[p.status for p in plans],
        objective=np.array([p.objective for p in plans]), iterations=np.array([p.iterations for p in plans]),
        solve_ms=np.array([p.solve_ms for p in plans]), round_trip_ms=np.array([p.round_trip_ms for p in plans]),
        has_plan=np.array([p.has_plan for p in plans]), input_bounds=(in_lo[0], in_hi[0]),
        output_bounds=(out_lo[row], out_hi[row]), plans=plans)
