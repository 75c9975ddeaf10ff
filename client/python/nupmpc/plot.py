"""Trajectory figures (matplotlib, imported only here: plots are optional).

Panels, by axes title: "States", "Outputs" (with bounds and references), "Inputs" (with
limits), "Solve and round-trip time". Built on a Figure with the Agg canvas, not pyplot,
so nothing depends on a display or on pyplot's global state."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from nupmpc.arrays import ArrayLike

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from nupmpc.simulate import Trajectory


def _bound_lines(ax: Axes, values: ArrayLike, steps: int, label: str, style: str) -> None:
    """One horizontal line per distinct finite bound (a shared limit is drawn once)."""
    for v in sorted({float(v) for v in np.atleast_1d(values) if np.isfinite(v)}):
        ax.plot([0, steps], [v, v], style, color="0.3", linewidth=1.0, label=f"{label} {v:g}")


def plot_trajectory(trajectory: Trajectory, path: str | os.PathLike[str] | None = None,
                    title: str | None = None) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    T = trajectory.steps
    has_outputs = trajectory.y.shape[1] > 0
    panels = 4 if has_outputs else 3
    fig = Figure(figsize=(9, 2.6 * panels), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(panels, 1, sharex=True)
    t_states = np.arange(T + 1)
    t_steps = np.arange(T)

    ax = axes[0]
    ax.set_title("States")
    for m in range(trajectory.x.shape[1]):
        ax.plot(t_states, trajectory.x[:, m], label=f"x{m}")

    if has_outputs:
        ax = axes[1]
        ax.set_title("Outputs")
        for k in range(trajectory.y.shape[1]):
            line, = ax.plot(t_steps, trajectory.y[:, k], label=f"y{k}")
            ref = trajectory.references[:, k]
            if np.isfinite(ref).any() and np.nanmax(np.abs(ref)) > 0:
                ax.plot(t_steps, ref, ":", color=line.get_color(), label=f"y{k} reference")
        _bound_lines(ax, trajectory.output_bounds[1], T, "y ≤", "--")
        _bound_lines(ax, trajectory.output_bounds[0], T, "y ≥", "--")

    ax = axes[-2]
    ax.set_title("Inputs")
    for l in range(trajectory.u.shape[1]):
        ax.step(t_steps, trajectory.u[:, l], where="post", label=f"u{l}")
    _bound_lines(ax, trajectory.input_bounds[1], T, "u ≤", "--")
    _bound_lines(ax, trajectory.input_bounds[0], T, "u ≥", "--")

    ax = axes[-1]
    ax.set_title("Solve and round-trip time")
    ax.plot(t_steps, trajectory.solve_ms, label="solve (server)")
    ax.plot(t_steps, trajectory.round_trip_ms, label="round trip (client)")
    ax.set_ylabel("ms")
    ax.set_xlabel("control period")
    for ax in axes:
        # Many states or outputs: keep the legend beside the panel, small.
        ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize="small", ncol=2 if len(ax.lines) > 8 else 1)
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=90)
    return fig
