"""GP-MPC specs from logged data (proto GpMpc)."""

import math

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import as_array, expand, finite, vector
from nupmpc.errors import ShapeError
from nupmpc.spec_builder import _Spec

INF = math.inf


class GpProblem(_Spec):
    """GP-MPC on a single-input single-output plant learned from data (proto GpMpc).

    `outputs`, `inputs`: a logged experiment y[0..T-1], u[0..T-1]. The session's state is
    the past window [y[t-l..t-1], u[t-m-1..t-1]] (M = l + m + 1); Step.reference replaces r."""

    def __init__(self, outputs, inputs, output_lags=1, input_lags=0, horizon=None, output_weight=1.0,
                 input_change_weight=1.0, input_bounds=None, rate_bounds=None, output_bounds=(-INF, INF),
                 sigma_multiple=0.0, terminal_tolerance=0.0, reference=0.0, kernel=None, window=None):
        if horizon is None or int(horizon) != horizon or horizon < 1:
            raise ShapeError("horizon", f"must be an integer ≥ 1, got {horizon!r}")
        y = finite(as_array(outputs, "outputs", ndim_max=1), "outputs")
        u = finite(as_array(inputs, "inputs", ndim_max=1), "inputs")
        if y.ndim != 1 or u.shape != y.shape:
            raise ShapeError("inputs", f"expected the same length as outputs {y.shape}, got {u.shape}")
        for name, bounds in (("input_bounds", input_bounds), ("rate_bounds", rate_bounds)):
            if bounds is None or len(bounds) != 2 or not (np.isfinite(bounds).all() and bounds[0] < bounds[1]):
                raise ShapeError(name, "required: finite (min, max) with min < max")
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

    @classmethod
    def _wrap(cls, spec):
        self = cls.__new__(cls)
        _Spec.__init__(self, spec)
        return self

    M = property(lambda self: max(self._spec.gp.model.output_lags, 1) + self._spec.gp.model.input_lags + 1)
    L = property(lambda self: 1)
    K = property(lambda self: 1)
    N = property(lambda self: self._spec.gp.horizon)

    def bounds(self, which):
        gp, steps = self._spec.gp, self.N + (which != "input")
        lo, hi = (gp.input_min, gp.input_max) if which == "input" else (gp.output_min, gp.output_max)
        return np.full((steps, 1), lo), np.full((steps, 1), hi)

    def output_references(self):
        ref = np.full((self.N + 1, 1), np.nan)
        ref[1:, 0] = expand(self._spec.gp.reference, self.N) if self._spec.gp.reference else 0.0
        return ref
