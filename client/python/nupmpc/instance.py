"""The problem files of the command-line tools: an instance in the benchmarks/
format (recognised by its "dims" key) or a ProblemSpec in proto JSON.

The instance → ProblemSpec conversion mirrors client/problem_file.cc exactly (the C++
reader the CLI uses), so a spec loaded here is the spec `nupmpc solve FILE` sends: change
one, change the other (the pytest suite compares their objectives on every instance).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Optional

import numpy as np
from google.protobuf import json_format

from nupmpc._proto import pb
from nupmpc.arrays import FloatArray
from nupmpc.spec_builder import from_spec

if TYPE_CHECKING:
    from nupmpc.gp_problem import GpProblem
    from nupmpc.problem import Problem

# A parsed JSON object, and a table of optional numbers by (step, component).
_Json = dict[str, Any]
_Table = Callable[[int, int], Optional[float]]
# One step of a component: (lower, upper, weight, target), None for an absent bound.
_StepPrior = tuple[Optional[float], Optional[float], float, float]

INF = math.inf


class InstanceError(ValueError):
    """A malformed instance file; `field` names the offending field."""

    def __init__(self, field: str, what: str) -> None:
        self.field = field
        super().__init__(f"{field}: {what}")


@dataclass
class Instance:
    name: str
    family: str
    _spec: pb.ProblemSpec
    closed_loop_states: FloatArray | None = field(default=None)  # (T, M) recorded x1 per step, or None

    @property
    def spec(self) -> pb.ProblemSpec:
        """A copy of the instance's ProblemSpec (yours to change)."""
        copy = pb.ProblemSpec()
        copy.CopyFrom(self._spec)
        return copy

    @property
    def problem(self) -> Problem | GpProblem:
        """The spec as a builder (Problem or GpProblem)."""
        return from_spec(self._spec)


def _member(obj: _Json, name: str) -> Any:
    return obj.get(name)  # absent and null alike: None


def _required(obj: _Json, name: str) -> Any:
    value = _member(obj, name)
    if value is None:
        raise InstanceError(name, "required")
    return value


def _list(value: Any, field_name: str) -> list[Any]:
    if not isinstance(value, list):
        raise InstanceError(field_name, "expected a list")
    return value


def _number(value: Any, field_name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InstanceError(field_name, "expected a number")
    return float(value)


def _count(obj: _Json, name: str, field_name: str) -> int:
    if _member(obj, name) is None:
        raise InstanceError(field_name, "required")
    x = _number(obj[name], field_name)
    if not (0.0 <= x <= 1e9 and math.floor(x) == x):
        raise InstanceError(field_name, "expected a count")
    return int(x)


def _numbers(value: Any, field_name: str) -> list[float]:
    return [_number(v, f"{field_name}[{i}]") for i, v in enumerate(_list(value, field_name))]


def _matrix(value: Any, field_name: str) -> pb.Matrix:
    """A row-major nested list as a pb.Matrix of its own shape (the server checks it)."""
    rows = _list(value, field_name)
    out = pb.Matrix(rows=len(rows), cols=0)
    for i, row in enumerate(rows):
        values = _numbers(row, f"{field_name}[{i}]")
        if i == 0:
            out.cols = len(values)
        if len(values) != out.cols:
            raise InstanceError(f"{field_name}[{i}]", "rows of different lengths")
        out.data.extend(values)
    return out


def _diagonal(value: Any, field_name: str, size: int) -> list[float]:
    m = _matrix(value, field_name)
    if m.rows != size or m.cols != size:
        raise InstanceError(field_name, f"expected {size}x{size}")
    diagonal = [0.0] * size
    for i in range(size):
        for j in range(size):
            x = m.data[i * size + j]
            if i == j:
                diagonal[i] = x
            elif x != 0.0:
                raise InstanceError(field_name, "only diagonal weights are supported")
    return diagonal


def _bound_table(doc: _Json, name: str, steps: int, dim: int) -> _Table:
    """An optional steps×dim table of numbers or nulls; a function (n, i) → value or None."""
    value = _member(doc, name)
    if value is None:
        return lambda n, i: None
    rows = _list(value, name)
    if len(rows) < steps:
        raise InstanceError(name, f"expected {steps} rows")
    entries: dict[tuple[int, int], float] = {}
    for n in range(steps):
        row_field = f"{name}[{n}]"
        row = _list(rows[n], row_field)
        if len(row) < dim:
            raise InstanceError(row_field, f"expected {dim} entries")
        for i in range(dim):
            if row[i] is not None:
                entries[(n, i)] = _number(row[i], f"{row_field}[{i}]")
    return lambda n, i: entries.get((n, i))


def _compress(values: list[float]) -> list[float]:
    """Per-step values that are all equal become one (the proto's constant form)."""
    return values[:1] if all(v == values[0] for v in values[1:]) else values


def _component(steps: list[_StepPrior]) -> pb.ComponentPrior:
    """One component's ComponentPrior from its per-step (lower, upper, weight, target)."""
    any_lower = any(lo is not None and hi is None for lo, hi, _, _ in steps)
    any_upper = any(hi is not None and lo is None for lo, hi, _, _ in steps)
    any_both = any(lo is not None and hi is not None for lo, hi, _, _ in steps)
    absent = any(lo is None and hi is None for lo, hi, _, _ in steps)
    kinds = int(any_lower) + int(any_upper) + int(any_both)
    if kinds == 0:
        kind = pb.PRIOR_KIND_UNSPECIFIED
    elif kinds > 1 or absent or any_both:
        kind = pb.PRIOR_KIND_BOX
    else:
        kind = pb.PRIOR_KIND_AT_LEAST if any_lower else pb.PRIOR_KIND_AT_MOST
    out = pb.ComponentPrior(kind=kind)
    out.weight.extend(_compress([w if w > 0.0 else 0.0 for _, _, w, _ in steps]))
    out.target.extend(_compress([t if w > 0.0 else 0.0 for _, _, w, t in steps]))
    if kind in (pb.PRIOR_KIND_AT_LEAST, pb.PRIOR_KIND_BOX):
        out.lower.extend(_compress([-INF if lo is None else lo for lo, _, _, _ in steps]))
    if kind in (pb.PRIOR_KIND_AT_MOST, pb.PRIOR_KIND_BOX):
        out.upper.extend(_compress([INF if hi is None else hi for _, hi, _, _ in steps]))
    if kind != pb.PRIOR_KIND_UNSPECIFIED:
        out.slope.append(INF)  # hard bounds
    return out


def _read_instance(doc: _Json) -> tuple[pb.ProblemSpec, FloatArray | None]:
    dims = _required(doc, "dims")
    if not isinstance(dims, dict):
        raise InstanceError("dims", "expected an object")
    M, L = _count(dims, "M", "dims.M"), _count(dims, "L", "dims.L")
    K, N = _count(dims, "K", "dims.K"), _count(dims, "N", "dims.N")
    spec = pb.ProblemSpec()
    model = spec.model
    model.num_states, model.num_inputs, model.num_outputs, model.horizon = M, L, K, N
    model.a.append(_matrix(_required(doc, "A"), "A"))
    model.b.append(_matrix(_required(doc, "B"), "B"))
    if K != 0:
        model.c.append(_matrix(_required(doc, "C"), "C"))

    x0 = spec.initial_state
    if _member(doc, "x1") is not None:
        x0.mean.extend(_numbers(doc["x1"], "x1"))
    else:
        prior = _member(doc, "x1_prior")
        if prior is None:
            raise InstanceError("x1", "one of x1 and x1_prior is required")
        if not isinstance(prior, dict):
            raise InstanceError("x1_prior", "expected an object")
        if _member(prior, "mean") is None or _member(prior, "cov") is None:
            raise InstanceError("x1_prior", "needs mean and cov")
        x0.mean.extend(_numbers(prior["mean"], "x1_prior.mean"))
        x0.covariance.CopyFrom(_matrix(prior["cov"], "x1_prior.cov"))

    # Quadratic parts: R and Qy diagonal, u_ref the same at every step, y_ref per step.
    input_weight = _diagonal(doc["R"], "R", L) if _member(doc, "R") is not None else [0.0] * L
    u_ref = [0.0] * L
    if _member(doc, "u_ref") is not None:
        u_ref = _numbers(doc["u_ref"], "u_ref")
        if len(u_ref) != L:
            raise InstanceError("u_ref", f"expected {L} values")
    output_weight = _diagonal(doc["Qy"], "Qy", K) if _member(doc, "Qy") is not None else [0.0] * K
    y_ref = _bound_table(doc, "y_ref", N, K)
    u_min, u_max = _bound_table(doc, "u_min", N, L), _bound_table(doc, "u_max", N, L)
    y_min, y_max = _bound_table(doc, "y_min", N, K), _bound_table(doc, "y_max", N, K)

    # Inputs u[n] = u_{n+1}, n = 0..N-1; outputs y[n] = y_{n+1}, n = 0..N-1, none at n = N.
    for l in range(L):
        spec.input_priors.append(_component([(u_min(n, l), u_max(n, l), input_weight[l], u_ref[l])
                                             for n in range(N)]))
    for k in range(K):
        steps = [(y_min(n, k), y_max(n, k), output_weight[k], y_ref(n, k) or 0.0) for n in range(N)]
        steps.append((None, None, 0.0, 0.0))
        spec.output_priors.append(_component(steps))

    if _member(doc, "Qf") is not None:
        terminal = spec.terminal
        if _member(doc, "x_f") is not None:
            terminal.target.extend(_numbers(doc["x_f"], "x_f"))
        else:
            terminal.target.extend([0.0] * M)
        terminal.weight.CopyFrom(_matrix(doc["Qf"], "Qf"))

    states: FloatArray | None = None
    closed_loop = _member(doc, "closed_loop")
    if closed_loop is not None:
        if not isinstance(closed_loop, dict):
            raise InstanceError("closed_loop", "expected an object")
        if _member(closed_loop, "x1") is None:
            raise InstanceError("closed_loop.x1", "required")
        rows = _list(closed_loop["x1"], "closed_loop.x1")
        states = np.array([_numbers(x, f"closed_loop.x1[{t}]") for t, x in enumerate(rows)], dtype=float)
    return spec, states


def load_instance(path: str | os.PathLike[str]) -> Instance:
    """An Instance from a benchmark instance file or a ProblemSpec JSON file.
    ValueError naming the file and the field when malformed, OSError when unreadable."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    if '"dims"' in text:  # the benchmark format
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as error:
            raise ValueError(f"{path}: not JSON: {error}") from None
        if not isinstance(doc, dict):
            raise ValueError(f"{path}: malformed instance: expected an object")
        try:
            spec, states = _read_instance(doc)
        except InstanceError as error:
            error.args = (f"{path}: malformed instance: {error}",)
            raise
        name, family = doc.get("name"), doc.get("family")
        return Instance(name if isinstance(name, str) else "", family if isinstance(family, str) else "", spec, states)
    spec = pb.ProblemSpec()
    try:
        json_format.Parse(text, spec)
    except json_format.ParseError as error:
        raise ValueError(f"{path}: not a ProblemSpec: {error}") from None
    return Instance("", "", spec, None)
