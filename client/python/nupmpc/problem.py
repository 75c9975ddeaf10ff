"""Problem specs from numpy: a builder that writes a nupmpc.v1.ProblemSpec as it goes.

Every method checks its arguments against the model's dimensions (M states, L inputs,
K outputs, horizon N) and raises ShapeError naming the argument, so nothing malformed is
sent; rules that need the solver (e.g. a PSD weight) are the server's, whose errors name
the spec field. Per-step arguments take a scalar, one value per component, or one row per
step (N rows for inputs, N+1 for outputs); the proto header explains the conventions.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, FloatArray, as_array, expand, finite, matrices, matrix, per_step, vector
from nupmpc.errors import ShapeError
from nupmpc.spec_builder import _Spec, _set

if TYPE_CHECKING:
    from nupmpc._proto import RepeatedMessages
    from nupmpc.regions import Ellipse

INF = math.inf


class Problem(_Spec):
    """x[n+1] = A x[n] + B u[n] (+ offsets), y[n] = C x[n]; horizon N.

    A (M, M), B (M, L), C (K, M) or None (no outputs); a 3-D array (N or N+1 matrices) makes
    the model time-varying. Methods return the problem, so they chain."""

    def __init__(self, A: ArrayLike, B: ArrayLike, C: ArrayLike | None = None, horizon: int | None = None,
                 x0: ArrayLike | None = None, state_offset: ArrayLike | None = None,
                 output_offset: ArrayLike | None = None) -> None:
        if horizon is None or int(horizon) != horizon or horizon < 1:
            raise ShapeError("horizon", f"must be an integer ≥ 1, got {horizon!r}")
        N = int(horizon)
        a, b = as_array(A, "A"), as_array(B, "B")
        if a.ndim not in (2, 3) or a.shape[-1] != a.shape[-2]:
            raise ShapeError("A", f"expected a square matrix (M, M), got shape {a.shape}")
        M = a.shape[-1]
        if b.ndim not in (2, 3) or b.shape[-2] != M:
            raise ShapeError("B", f"expected shape ({M}, L), got {b.shape}")
        L = b.shape[-1]
        c = None if C is None else as_array(C, "C")
        if c is not None and (c.ndim not in (2, 3) or c.shape[-1] != M):
            raise ShapeError("C", f"expected shape (K, {M}), got {c.shape}")
        K = 0 if c is None else c.shape[-2]
        model = pb.Model(num_states=M, num_inputs=L, num_outputs=K, horizon=N)
        model.a.extend(matrices(a, "A", M, M, N))
        model.b.extend(matrices(b, "B", M, L, N))
        if c is not None:
            model.c.extend(matrices(c, "C", K, M, N + 1))
        if state_offset is not None:
            model.state_offset.extend(self._offsets(state_offset, "state_offset", N, M))
        if output_offset is not None:
            model.output_offset.extend(self._offsets(output_offset, "output_offset", N + 1, K))
        spec = pb.ProblemSpec(model=model)
        spec.input_priors.extend(pb.ComponentPrior() for _ in range(L))
        spec.output_priors.extend(pb.ComponentPrior() for _ in range(K))
        super().__init__(spec)
        self.initial_state(np.zeros(M) if x0 is None else x0)

    @staticmethod
    def _offsets(value: ArrayLike, name: str, steps: int, width: int) -> list[float]:
        array = finite(as_array(value, name, ndim_max=2), name)
        if array.shape not in ((width,), (steps, width)):
            raise ShapeError(name, f"expected shape ({width},) or ({steps}, {width}), got {array.shape}")
        values: list[float] = array.ravel().tolist()
        return values

    # Dimensions.
    @property
    def M(self) -> int:
        return self._spec.model.num_states

    @property
    def L(self) -> int:
        return self._spec.model.num_inputs

    @property
    def K(self) -> int:
        return self._spec.model.num_outputs

    @property
    def N(self) -> int:
        return self._spec.model.horizon

    def initial_state(self, mean: ArrayLike, covariance: ArrayLike | None = None) -> Problem:
        """x[0] (fixed), or a Gaussian prior of this mean and covariance (M, M)."""
        state = self._spec.initial_state
        _set(state.mean, finite(vector(mean, "x0", self.M), "x0").tolist())
        state.ClearField("covariance")
        if covariance is not None:
            state.covariance.CopyFrom(matrix(covariance, "covariance", self.M, self.M))
        return self

    # Priors of inputs and outputs.
    def _components(self, which: str) -> tuple[RepeatedMessages[pb.ComponentPrior], int, int]:
        if which == "input":
            return self._spec.input_priors, self.N, self.L
        if self.K == 0:
            raise ShapeError("C", "the model has no outputs (give C)")
        return self._spec.output_priors, self.N + 1, self.K

    def _box(self, which: str, name: str, lower: ArrayLike | None, upper: ArrayLike | None,
             soft: ArrayLike | None) -> Problem:
        components, steps, width = self._components(which)
        if lower is None and upper is None:
            raise ShapeError(name, "give lower, upper or both")
        lows = per_step(-INF if lower is None else lower, f"{name}.lower", steps, width)
        highs = per_step(INF if upper is None else upper, f"{name}.upper", steps, width)
        slopes = None if soft is None else per_step(soft, f"{name}.soft", steps, width)
        for i, prior in enumerate(components):
            if any(lo > hi for lo, hi in zip(np.broadcast_to(lows[i], steps), np.broadcast_to(highs[i], steps))):
                raise ShapeError(name, f"lower > upper for {which} {i}")
            if lower is not None and upper is not None:
                prior.kind = pb.PRIOR_KIND_BOX
            else:
                prior.kind = pb.PRIOR_KIND_AT_LEAST if upper is None else pb.PRIOR_KIND_AT_MOST
            _set(prior.lower, lows[i] if lower is not None else [])
            _set(prior.upper, highs[i] if upper is not None else [])
            _set(prior.slope, [] if slopes is None else slopes[i])
        return self

    def input_box(self, lower: ArrayLike | None = None, upper: ArrayLike | None = None,
                  soft: ArrayLike | None = None) -> Problem:
        """lower ≤ u ≤ upper (hard; `soft`: the penalty slope per unit outside it)."""
        return self._box("input", "input_box", lower, upper, soft)

    def output_box(self, lower: ArrayLike | None = None, upper: ArrayLike | None = None,
                   soft: ArrayLike | None = None) -> Problem:
        """lower ≤ y ≤ upper at steps 0..N (hard; `soft`: penalty slope)."""
        return self._box("output", "output_box", lower, upper, soft)

    def _quadratic(self, which: str, name: str, weight: ArrayLike, target: ArrayLike,
                   target_name: str) -> Problem:
        components, steps, width = self._components(which)
        weights = per_step(weight, f"{name}.weight", steps, width)
        targets = per_step(target, f"{name}.{target_name}", steps, width)
        if any(w < 0 for ws in weights for w in ws):
            raise ShapeError(f"{name}.weight", "must be ≥ 0")
        for i, prior in enumerate(components):
            _set(prior.weight, weights[i])
            _set(prior.target, targets[i])
        return self

    def input_weight(self, weight: ArrayLike, target: ArrayLike = 0.0) -> Problem:
        """½·weight·(u - target)² per input and step."""
        return self._quadratic("input", "input_weight", weight, target, "target")

    def output_weight(self, weight: ArrayLike, reference: ArrayLike = 0.0) -> Problem:
        """½·weight·(y - reference)² per output and step (reference: (K,) or (N+1, K))."""
        return self._quadratic("output", "output_weight", weight, reference, "reference")

    def references(self, reference: ArrayLike) -> Problem:
        """New output references, keeping the weights."""
        components, steps, width = self._components("output")
        targets = per_step(reference, "references", steps, width)
        for i, prior in enumerate(components):
            _set(prior.target, targets[i])
        return self

    def terminal_cost(self, weight: ArrayLike, target: ArrayLike | None = None) -> Problem:
        """½ (x[N] - target)ᵀ weight (x[N] - target); weight (M, M)."""
        self._spec.terminal.weight.CopyFrom(matrix(weight, "terminal_cost.weight", self.M, self.M))
        _set(self._spec.terminal.target, finite(vector(0.0 if target is None else target,
                                                       "terminal_cost.target", self.M), "terminal_cost.target").tolist())
        return self

    def input_rate(self, lower: ArrayLike | None = None, upper: ArrayLike | None = None,
                   weight: ArrayLike | None = None, soft: ArrayLike | None = None,
                   previous_input: ArrayLike | None = None) -> Problem:
        """Limits (and a quadratic penalty `weight`) on Δu[n] = u[n] - u[n-1]; u[-1] is
        `previous_input` (default zeros), then the u[0] of each plan."""
        differences = self._spec.input_differences
        if not differences.priors:
            differences.priors.extend(pb.ComponentPrior() for _ in range(self.L))
        N, L = self.N, self.L
        if lower is not None or upper is not None:
            lows = per_step(-INF if lower is None else lower, "input_rate.lower", N, L)
            highs = per_step(INF if upper is None else upper, "input_rate.upper", N, L)
            slopes = None if soft is None else per_step(soft, "input_rate.soft", N, L)
            for l, prior in enumerate(differences.priors):
                prior.kind = (pb.PRIOR_KIND_BOX if lower is not None and upper is not None else
                              pb.PRIOR_KIND_AT_LEAST if upper is None else pb.PRIOR_KIND_AT_MOST)
                _set(prior.lower, lows[l] if lower is not None else [])
                _set(prior.upper, highs[l] if upper is not None else [])
                _set(prior.slope, [] if slopes is None else slopes[l])
        if weight is not None:
            weights = per_step(weight, "input_rate.weight", N, L)
            for l, prior in enumerate(differences.priors):
                _set(prior.weight, weights[l])
        if previous_input is not None:
            _set(differences.previous_input, vector(previous_input, "previous_input", L).tolist())
        return self

    def input_levels(self, input: int, count: int, lowest: float, spacing: float) -> Problem:
        """Input `input` takes only the levels lowest + spacing·{0, …, count-1}."""
        if not 0 <= input < self.L:
            raise ShapeError("input_levels.input", f"must be < {self.L}")
        if count < 2 or not spacing > 0:
            raise ShapeError("input_levels", "count must be ≥ 2 and spacing > 0")
        self._spec.input_levels.add(input=input, count=count, lowest=lowest, spacing=spacing)
        return self

    def keep_out(self, first_output: int, second_output: int, regions: Sequence[Ellipse], rectangle_order: int = 0,
                 max_linearisations: int = 0, step_tolerance: float = 0.0) -> Problem:
        """The plan's point (y_first, y_second) stays outside every region (Ellipse, Rectangle)."""
        for name, k in (("first_output", first_output), ("second_output", second_output)):
            if not 0 <= k < self.K:
                raise ShapeError(f"keep_out.{name}", f"must be < {self.K} (the number of outputs)")
        if first_output == second_output:
            raise ShapeError("keep_out.second_output", "must differ from first_output")
        if not regions:
            raise ShapeError("keep_out.regions", "give at least one region")
        keep_out = self._spec.keep_out
        keep_out.first_output, keep_out.second_output = first_output, second_output
        del keep_out.regions[:]
        keep_out.regions.extend(r.to_proto() for r in regions)
        keep_out.rectangle_order = rectangle_order
        keep_out.max_linearisations = max_linearisations
        keep_out.step_tolerance = step_tolerance
        return self

    def options(self, algorithm: str | None = None, max_iterations: int = 0, objective_tolerance: float = 0.0,
                violation_tolerance: float = 0.0, time_limit_ms: float = 0.0, elastic_slope: float = 0.0,
                elastic_after_iterations: int = 0) -> Problem:
        """Solver options (0: the server's default); algorithm "IAKE", "IBFFD" or "IFFBDD"."""
        options = self._spec.options
        if algorithm is not None:
            try:
                options.algorithm = pb.Algorithm.Value(f"ALGORITHM_{str(algorithm).upper()}")
            except ValueError:
                raise ShapeError("algorithm", f"unknown algorithm {algorithm!r}") from None
        options.max_iterations = max_iterations
        options.objective_tolerance = objective_tolerance
        options.violation_tolerance = violation_tolerance
        options.time_limit_ms = time_limit_ms
        options.elastic_slope = elastic_slope
        options.elastic_after_iterations = elastic_after_iterations
        return self

    # What the plots draw.
    def bounds(self, which: str) -> tuple[FloatArray, FloatArray]:
        """(lower, upper) per step, shape (steps, width), ±inf where absent."""
        components, steps, width = (self._spec.input_priors, self.N, self.L) if which == "input" else \
            (self._spec.output_priors, self.N + 1, self.K)
        lower = np.full((steps, width), -INF)
        upper = np.full((steps, width), INF)
        for i, p in enumerate(components):
            if p.kind in (pb.PRIOR_KIND_AT_LEAST, pb.PRIOR_KIND_BOX) and p.lower:
                lower[:, i] = expand(p.lower, steps)
            if p.kind in (pb.PRIOR_KIND_AT_MOST, pb.PRIOR_KIND_BOX) and p.upper:
                upper[:, i] = expand(p.upper, steps)
        return lower, upper

    def output_references(self) -> FloatArray:
        """The output targets per step (N+1, K); NaN for outputs without a weight."""
        out = np.full((self.N + 1, self.K), np.nan)
        for k, p in enumerate(self._spec.output_priors):
            if any(w > 0 for w in p.weight):
                out[:, k] = expand(p.target, self.N + 1) if p.target else 0.0
        return out

