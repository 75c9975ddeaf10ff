"""A Step (one control period) from numpy arguments, checked against the session's spec.

Updates of references and bounds are whole ComponentPriors on the wire (PriorUpdate
replaces the listed components); they are built from the session's current spec (kept
current by apply_step_to_spec), shifted first when the step shifts, so that only what the
caller gives changes. Model updates (Step.model) come from a nupmpc.ModelUpdate, checked
against the spec's dimensions, or as a pb.ModelUpdate sent as it is (the server checks it)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal, Optional, Sequence, Union

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, as_array, finite, per_step, vector
from nupmpc.errors import ShapeError
from nupmpc.model_update import ModelUpdate
from nupmpc.spec_builder import _set
from nupmpc.spec_update import shift_components

if TYPE_CHECKING:
    from nupmpc._proto import RepeatedMessages

# How a step starts its solve: None (the server's default, "shift"), "shift", "keep" or "cold".
WarmStart = Optional[Literal["shift", "keep", "cold"]]
# (lower, upper) of a step's bounds, None for a side kept.
Bounds = tuple[Optional[ArrayLike], Optional[ArrayLike]]
# The model terms of one step: checked (nupmpc.ModelUpdate) or sent as they are.
StepModel = Union[ModelUpdate, pb.ModelUpdate]
# (M, L, K, N): states, inputs, outputs, horizon.
Dims = tuple[int, int, int, int]

_WARM: dict[str | None, pb.WarmStart] = {None: pb.WARM_START_UNSPECIFIED, "shift": pb.WARM_START_SHIFT,
                                          "keep": pb.WARM_START_KEEP, "cold": pb.WARM_START_COLD}


def dims_of(spec: pb.ProblemSpec) -> Dims:
    """(M, L, K, N) of a spec (GP: the past window, one input and output, horizon H)."""
    if spec.HasField("gp"):
        model = spec.gp.model
        return max(model.output_lags, 1) + model.input_lags + 1, 1, 1, spec.gp.horizon
    m = spec.model
    return m.num_states, m.num_inputs, m.num_outputs, m.horizon


def _pair(value: Bounds | None, name: str) -> Bounds:
    if value is None:
        return None, None
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ShapeError(name, "expected a pair (lower, upper); None for an absent side")
    return value


def _update_components(current: Sequence[pb.ComponentPrior], count: int, steps: int, which: str,
                       references: ArrayLike | None, bounds: Bounds | None,
                       entries: RepeatedMessages[pb.PriorUpdate.Entry]) -> None:
    """Adds PriorUpdate entries for the components whose reference or bounds change."""
    targets = None if references is None else per_step(references, f"{which}references", steps, count)
    lower, upper = _pair(bounds, f"{which}bounds")
    lows = None if lower is None else per_step(lower, f"{which}bounds.lower", steps, count)
    highs = None if upper is None else per_step(upper, f"{which}bounds.upper", steps, count)
    if targets is None and lows is None and highs is None:
        return
    for i in range(count):
        prior = pb.ComponentPrior()
        prior.CopyFrom(current[i])
        if targets is not None:
            _set(prior.target, targets[i])
        if lows is not None or highs is not None:
            if prior.kind not in (pb.PRIOR_KIND_UNSPECIFIED, pb.PRIOR_KIND_AT_LEAST, pb.PRIOR_KIND_AT_MOST,
                                  pb.PRIOR_KIND_BOX):
                raise ShapeError(f"{which}bounds", f"component {i} has a {pb.PriorKind.Name(prior.kind)} prior, not bounds")
            lo = lows[i] if lows is not None else (list(prior.lower) if prior.kind != pb.PRIOR_KIND_AT_MOST else [-math.inf])
            hi = highs[i] if highs is not None else (list(prior.upper) if prior.kind != pb.PRIOR_KIND_AT_LEAST else [math.inf])
            prior.kind = pb.PRIOR_KIND_BOX
            _set(prior.lower, lo or [-math.inf])
            _set(prior.upper, hi or [math.inf])
        entries.add(index=i, prior=prior)


def _model(spec: pb.ProblemSpec, model: StepModel | None, step: pb.Step) -> None:
    if model is None:
        return
    if isinstance(model, pb.ModelUpdate):
        step.model.CopyFrom(model)  # as given: the server checks it
    elif isinstance(model, ModelUpdate):
        step.model.CopyFrom(model.to_proto(spec))
    else:
        raise ShapeError("model", f"expected a nupmpc.ModelUpdate, got {type(model).__name__}")


def build_step(spec: pb.ProblemSpec, x: ArrayLike | None = None, *, references: ArrayLike | None = None,
               bounds: Bounds | None = None, input_references: ArrayLike | None = None,
               input_bounds: Bounds | None = None, shift: bool = False, warm_start: WarmStart = None,
               max_iterations: int = 0, time_limit_ms: float = 0.0, previous_input: ArrayLike | None = None,
               model: StepModel | None = None) -> pb.Step:
    """The Step for `session.step(...)`; see Session.step for the arguments."""
    M, L, K, N = dims_of(spec)
    step = pb.Step(max_iterations=max_iterations, time_limit_ms=time_limit_ms)
    if warm_start not in _WARM:
        raise ShapeError("warm_start", f"one of 'shift', 'keep', 'cold'; got {warm_start!r}")
    step.warm_start = _WARM[warm_start]
    if x is not None:
        step.state.extend(finite(vector(x, "x", M), "x").tolist())
    _model(spec, model, step)
    if spec.HasField("gp"):
        if bounds is not None or input_references is not None or input_bounds is not None or shift:
            raise ShapeError("bounds", "a GP session takes only x and references (its bounds are fixed)")
        if references is not None:
            r = finite(as_array(references, "references", ndim_max=1), "references")
            r = np.atleast_1d(r)
            if len(r) not in (1, N):
                raise ShapeError("references", f"expected 1 or {N} values, got {len(r)}")
            step.reference.extend(r.tolist())
        return step
    if previous_input is not None:
        if not spec.HasField("input_differences"):
            raise ShapeError("previous_input", "only for a problem with input_rate")
        step.previous_input.extend(finite(vector(previous_input, "previous_input", L), "previous_input").tolist())
    if references is not None and K == 0:
        raise ShapeError("references", "the model has no outputs")
    current_in, current_out = list(spec.input_priors), list(spec.output_priors)
    if shift:
        step.update.shift = True
        copy = pb.ProblemSpec()
        copy.CopyFrom(spec)
        shift_components(copy.input_priors)
        shift_components(copy.output_priors)
        current_in, current_out = list(copy.input_priors), list(copy.output_priors)
    _update_components(current_out, K, N + 1, "", references, bounds, step.update.outputs)
    _update_components(current_in, L, N, "input_", input_references, input_bounds, step.update.inputs)
    return step
