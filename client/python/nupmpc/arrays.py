"""numpy arguments → the proto's flat arrays, checking shapes and naming the argument on
every refusal (ShapeError), so a wrong shape never reaches the server."""

from __future__ import annotations

from typing import Iterable

import numpy as np
import numpy.typing as npt


from nupmpc._proto import pb
from nupmpc.errors import ShapeError

# What the client takes (anything numpy reads as numbers) and what it returns.
ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]


def as_array(value: ArrayLike, name: str, ndim_max: int = 3) -> FloatArray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise ShapeError(name, f"expected numbers ({error})") from None
    if array.ndim > ndim_max:
        raise ShapeError(name, f"expected at most {ndim_max} dimensions, got shape {array.shape}")
    if np.isnan(array).any():
        raise ShapeError(name, "contains NaN")
    return array


def finite(array: FloatArray, name: str) -> FloatArray:
    if not np.isfinite(array).all():
        raise ShapeError(name, "must be finite")
    return array


def vector(value: ArrayLike, name: str, size: int) -> FloatArray:
    """A length-`size` vector (a scalar is repeated)."""
    array = as_array(value, name, ndim_max=1)
    if array.ndim == 0:
        array = np.full(size, float(array))
    if array.shape != (size,):
        raise ShapeError(name, f"expected shape ({size},), got {array.shape}")
    return array


def matrix(value: ArrayLike, name: str, rows: int, cols: int) -> pb.Matrix:
    """A pb.Matrix of shape rows×cols (finite)."""
    array = finite(as_array(value, name, ndim_max=2), name)
    if array.ndim == 1 and rows == 1:
        array = array.reshape(1, -1)
    if array.ndim == 0 and rows == 1 and cols == 1:
        array = array.reshape(1, 1)
    if array.shape != (rows, cols):
        raise ShapeError(name, f"expected shape ({rows}, {cols}), got {array.shape}")
    return pb.Matrix(rows=rows, cols=cols, data=array.ravel().tolist())


def matrices(value: ArrayLike, name: str, rows: int, cols: int, steps: int) -> list[pb.Matrix]:
    """One matrix (time-invariant) or `steps` of them (a 3-D array), as a list of pb.Matrix."""
    array = as_array(value, name)
    if array.ndim == 3:
        if array.shape[0] != steps:
            raise ShapeError(name, f"a time-varying {name} needs {steps} matrices, got {array.shape[0]}")
        return [matrix(a, f"{name}[{n}]", rows, cols) for n, a in enumerate(array)]
    return [matrix(array, name, rows, cols)]


def per_step(value: ArrayLike, name: str, steps: int, width: int) -> list[list[float]]:
    """Per-component, per-step values: a scalar (everything), shape (width,) (one value per
    component at every step) or (steps, width). Returns `width` lists, each of length 1 (the
    same at every step, the proto's short form) or `steps`."""
    array = as_array(value, name, ndim_max=2)
    if array.ndim == 0:
        return [[float(array)] for _ in range(width)]
    if array.ndim == 1:
        if array.shape != (width,):
            raise ShapeError(name, f"expected a scalar, shape ({width},) or ({steps}, {width}); got {array.shape}")
        return [[float(v)] for v in array]
    if array.shape == (1, width):
        return [[float(v)] for v in array[0]]
    if array.shape != (steps, width):
        raise ShapeError(name, f"expected a scalar, shape ({width},) or ({steps}, {width}); got {array.shape}")
    return [array[:, i].tolist() for i in range(width)]


def expand(values: Iterable[float], steps: int) -> FloatArray:
    """A proto per-step array (length 0, 1 or `steps`) as `steps` values (NaN when empty)."""
    given = list(values)
    if not given:
        return np.full(steps, np.nan)
    if len(given) == 1:
        return np.full(steps, given[0])
    return np.asarray(given[:steps], dtype=float)
