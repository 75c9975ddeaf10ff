"""GP-MPC specs from logged data (proto GpMpc)."""

from __future__ import annotations

import math

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, FloatArray, as_array, expand, finite, vector
from nupmpc.errors import ShapeError
from nupmpc.spec_builder import _Spec

INF = math.inf


def _required_bounds(name: str, bounds: tuple[float, float] | None) -> tuple[float, float]:
    if bounds is None or len(bounds) != 2 or not (np.isfinite(bounds).all() and bounds[0] < bounds[1]):
        raise ShapeError(name, "required: finite (min, max) with min < max")
    return bounds


class GpProblem(_Spec):
    """GP-MPC on a single-input single-output plant learned from data (proto GpMpc).

    `outputs`, `inputs`: a logged experiment y[0..T-1], u[0..T-1]. The session's state is
    the past window [y[t-l..t-1], u[t-m-1..t-1]] (M = l + m + 1); Step.reference replaces r."""

    def __init__(self, outputs: ArrayLike, inputs: ArrayLike, output_lags: int = 1, input_lags: int = 0,
                 horizon: int | None = None, output_weight: float = 1.0, input_change_weight: float = 1.0,
                 input_bounds: tuple[float, float] | None = None, rate_bounds: tuple[float, float] | None = None,
                 output_bounds: tuple[float, float] = (-INF, INF), sigma_multiple: float = 0.0,
                 terminal_tolerance: float = 0.0, reference: ArrayLike = 0.0, kernel: pb.GpKernel | None = None,
                 window: ArrayLike | None = None) -> None:
        if horizon is None or int(horizon) != horizon or horizon < 1:
            raise ShapeError("horizon", f"must be an integer ≥ 1, got {horizon!r}")
        y = finite(as_array(outputs, "outputs", ndim_max=1), "outputs")
        u = finite(as_array(inputs, "inputs", ndim_max=1), "inputs")
        if y.ndim != 1 or u.shape != y.shape:
            raise ShapeError("inputs", f"expected the same length as outputs {y.shape}, got {u.shape}")
        input_bounds = _required_bounds("input_bounds", input_bounds)
        rate_bounds = _required_bounds("rate_bounds", rate_bounds)
        if not output_bounds[0] < output_bounds[1]:
            raise ShapeError("output_bounds", "min must be < max")
        model = pb.GpModel(output_lags=output_lags, input_lags=input_lags, logged_outputs=y.tolist(),
                           logged_inputs=u.tolist())
        if kernel is not None:
            model.kernel.CopyFrom(kernel)
        reference = as_array(reference, "reference", ndim_max=1)
        if reference.ndim == 1 and len(reference) not in (1, horizon):
            raise ShapeError("reference", f"expected 1 or {horizon} values, got {len(reference)}")
        gp = pb.GpMpc(model=model, horizon=int(horizon), output_weight=output_weight,
                      input_change_weight=input_change_weight, input_min=input_bounds[0], input_max=input_bounds[1],
                      rate_min=rate_bounds[0], rate_max=rate_bounds[1], output_min=output_bounds[0],
                      output_max=output_bounds[1], sigma_multiple=sigma_multiple,
                      terminal_tolerance=terminal_tolerance, reference=np.atleast_1d(reference).tolist())
        spec = pb.ProblemSpec(gp=gp)
        if window is not None:
            spec.initial_state.mean.extend(vector(window, "window", output_lags + input_lags + 1).tolist())
        super().__init__(spec)

    @property
    def M(self) -> int:
        return max(self._spec.gp.model.output_lags, 1) + self._spec.gp.model.input_lags + 1

    @property
    def L(self) -> int:
        return 1

    @property
    def K(self) -> int:
        return 1

    @property
    def N(self) -> int:
        return self._spec.gp.horizon

    def bounds(self, which: str) -> tuple[FloatArray, FloatArray]:
        gp, steps = self._spec.gp, self.N + (which != "input")
        lo, hi = (gp.input_min, gp.input_max) if which == "input" else (gp.output_min, gp.output_max)
        return np.full((steps, 1), lo), np.full((steps, 1), hi)

    def output_references(self) -> FloatArray:
        ref = np.full((self.N + 1, 1), np.nan)
        ref[1:, 0] = expand(self._spec.gp.reference, self.N) if self._spec.gp.reference else 0.0
        return ref
