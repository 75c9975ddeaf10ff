"""New model terms for one control period (Step.model): x[n+1] = A[n] x[n] + B[n] u[n] + c[n],
y[n] = C[n] x[n] + d[n].

    session.step(x, model=nupmpc.ModelUpdate(A={3: A3}, state_offset=d_hat))
    session.step(x, model=nupmpc.ModelUpdate(A=A_all, B=B_all, C=C_all,        # (N, M, M), (N, M, L),
                                              state_offset=c_all,               # (N+1, K, M), (N, M),
                                              output_offset=d_all))             # (N+1, K)
    session.step(x, model=nupmpc.ModelUpdate(shift=True, A={N - 1: A_new}))     # receding horizon

Every argument is checked against the session's dimensions before anything is sent
(ShapeError naming it, e.g. "model.A[3]"). The server applies the update in this order:
shift, then the all-step offsets, then the single steps; a rejected update leaves the
session as it was. A time-invariant matrix given for some steps becomes per-step (the other
steps keep its value), which restarts the warm start once; sessions whose model is stored
per step (created with N matrices) keep it."""

from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, Iterable, Union

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, FloatArray, as_array, finite, matrix, vector
from nupmpc.errors import ShapeError

if TYPE_CHECKING:
    from nupmpc._proto import RepeatedMessages, RepeatedScalars

# A model term: one value for every step, one per step, or a dict {step: value} (those steps).
StepTerms = Union[ArrayLike, dict[int, ArrayLike]]


class ModelUpdate:
    """Model terms replacing the session's for this period (all optional).

    A, B, C: a dict {step: matrix} (those steps), an array with one matrix per step
      ((N, M, M), (N, M, L), (N+1, K, M): every step), or one matrix (the same at every step,
      sent as one entry per step);
    state_offset (c, steps < N), output_offset (d, steps ≤ N): a vector ((M,) or (K,), a scalar
      repeated: every step), an array with one row per step ((N, M) or (N+1, K)), or a dict
      {step: vector};
    shift: first move every per-step term one step earlier (step n+1 becomes step n, the last
      repeated), as the horizon moves; time-invariant terms stay.
    """

    def __init__(self, A: StepTerms | None = None, B: StepTerms | None = None, C: StepTerms | None = None,
                 state_offset: StepTerms | None = None, output_offset: StepTerms | None = None,
                 shift: bool = False) -> None:
        self.A, self.B, self.C = A, B, C
        self.state_offset, self.output_offset = state_offset, output_offset
        self.shift = bool(shift)

    def __repr__(self) -> str:
        given = [name for name in ("A", "B", "C", "state_offset", "output_offset") if getattr(self, name) is not None]
        return f"ModelUpdate({', '.join(given)}{', shift' if self.shift else ''})"

    def to_proto(self, spec: pb.ProblemSpec) -> pb.ModelUpdate:
        """The pb.ModelUpdate for a session created from `spec` (checked against its
        dimensions and the kind of session; ShapeError naming the argument)."""
        refuse_model_update(spec)
        m = spec.model
        M, L, K, N = m.num_states, m.num_inputs, m.num_outputs, m.horizon
        update = pb.ModelUpdate(shift=self.shift)
        _matrices(self.A, "model.A", N, "N", M, M, update.a)
        _matrices(self.B, "model.B", N, "N", M, L, update.b)
        if self.C is not None and K == 0:
            raise ShapeError("model.C", "the model has no outputs")
        _matrices(self.C, "model.C", N + 1, "N + 1", K, M, update.c)
        _offsets(self.state_offset, "model.state_offset", N, "N", M, update.state_offsets, update.state_offset)
        if self.output_offset is not None and K == 0:
            raise ShapeError("model.output_offset", "the model has no outputs")
        _offsets(self.output_offset, "model.output_offset", N + 1, "N + 1", K, update.output_offsets,
                 update.output_offset)
        if spec.HasField("keep_out"):
            # The server's rule: a keep-out session cannot change the storage of its matrices.
            for name, given, stored in (("A", update.a, m.a), ("B", update.b, m.b), ("C", update.c, m.c)):
                if len(given) and len(stored) == 1:
                    raise ShapeError(f"model.{name}", "a keep-out session takes per-step entries only for matrices "
                                                      "it stores per step: create it with one matrix per step")
        return update


def refuse_model_update(spec: pb.ProblemSpec) -> None:
    """ShapeError("model") for sessions that take no model update (GP, multi-level inputs, Δu)."""
    if spec.HasField("gp"):
        raise ShapeError("model", "a GP session takes no model update")
    if len(spec.input_levels):
        raise ShapeError("model", "a session with input_levels takes no model update")
    if spec.HasField("input_differences"):
        raise ShapeError("model", "a session with input_rate (input differences) takes no model update")


def _step_index(key: object, name: str, steps: int, steps_name: str) -> int:
    if isinstance(key, bool) or not isinstance(key, numbers.Integral):
        raise ShapeError(name, f"steps are integers, got {key!r}")
    if not 0 <= int(key) < steps:
        raise ShapeError(name, f"step {key} out of range: must be ≥ 0 and < {steps_name} = {steps}")
    return int(key)


def _by_step(value: dict[int, ArrayLike], name: str, steps: int, steps_name: str) -> list[tuple[int, ArrayLike]]:
    """The entries of a dict {step: value}, checked and in step order."""
    return sorted(((_step_index(key, name, steps, steps_name), given) for key, given in value.items()),
                  key=lambda entry: entry[0])


def _matrices(value: StepTerms | None, name: str, steps: int, steps_name: str, rows: int, cols: int,
              out: RepeatedMessages[pb.ModelUpdate.MatrixAt]) -> None:
    if value is None:
        return
    if isinstance(value, dict):
        for n, given in _by_step(value, name, steps, steps_name):
            out.add(step=n, matrix=matrix(given, f"{name}[{n}]", rows, cols))
        return
    array = as_array(value, name)
    if array.ndim == 3:
        if array.shape[0] != steps:
            raise ShapeError(name, f"one matrix per step needs {steps_name} = {steps} matrices, got shape "
                                   f"{array.shape}")
        if array.shape[1:] != (rows, cols):
            raise ShapeError(name, f"expected shape ({steps}, {rows}, {cols}), got {array.shape}")
        bad = np.flatnonzero(~np.isfinite(array).reshape(steps, -1).all(axis=1))
        if len(bad):
            raise ShapeError(f"{name}[{bad[0]}]", "must be finite")
        for n, a in enumerate(array):
            out.add(step=n, matrix=pb.Matrix(rows=rows, cols=cols, data=a.ravel().tolist()))
        return
    one = matrix(array, name, rows, cols)
    for n in range(steps):
        out.add(step=n, matrix=one)


def _offsets(value: StepTerms | None, name: str, steps: int, steps_name: str, width: int,
             all_steps: RepeatedScalars[float], entries: RepeatedMessages[pb.ModelUpdate.VectorAt]) -> None:
    if value is None:
        return
    if isinstance(value, dict):
        for n, given in _by_step(value, name, steps, steps_name):
            entries.add(step=n, values=finite(vector(given, f"{name}[{n}]", width), f"{name}[{n}]").tolist())
        return
    array = as_array(value, name, ndim_max=2)
    if array.ndim == 2:
        if array.shape not in ((steps, width), (1, width)):
            raise ShapeError(name, f"expected shape ({width},) (every step) or ({steps}, {width}) (one row per step), "
                                   f"got {array.shape}")
        all_steps.extend(finite(array, name).ravel().tolist())
        return
    if array.ndim == 1 and array.shape != (width,):
        raise ShapeError(name, f"expected shape ({width},) (every step) or ({steps}, {width}) (one row per step), "
                               f"got {array.shape}")
    all_steps.extend(finite(vector(array, name, width), name).tolist())


def model_terms(spec: pb.ProblemSpec) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The model terms of `spec` per step: A (N, M, M), B (N, M, L), C (N+1, K, M),
    c (N, M), d (N+1, K) (time-invariant terms repeated, absent offsets zero)."""
    m = spec.model
    M, L, K, N = m.num_states, m.num_inputs, m.num_outputs, m.horizon

    def stack(matrices: Iterable[pb.Matrix], steps: int, rows: int, cols: int) -> FloatArray:
        arrays = [np.asarray(a.data, dtype=float).reshape(rows, cols) for a in matrices]
        if not arrays:
            return np.zeros((steps, rows, cols))
        return np.stack(arrays if len(arrays) == steps else [arrays[0]] * steps)

    def rows(values: Iterable[float], steps: int, width: int) -> FloatArray:
        array = np.asarray(values, dtype=float)
        if array.size == 0:
            return np.zeros((steps, width))
        return np.tile(array, (steps, 1)) if array.size == width else array.reshape(steps, width)

    return (stack(m.a, N, M, M), stack(m.b, N, M, L), stack(m.c, N + 1, K, M), rows(m.state_offset, N, M),
            rows(m.output_offset, N + 1, K))
