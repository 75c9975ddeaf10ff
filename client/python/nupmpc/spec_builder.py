"""What every spec builder (Problem, GpProblem) shares: the ProblemSpec it writes, a copy
of it, and the round trip through the proto JSON that `nupmpc solve FILE` reads."""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterable, TypeVar

from google.protobuf import json_format

from nupmpc._proto import pb
from nupmpc.errors import ShapeError

if TYPE_CHECKING:
    from nupmpc._proto import RepeatedScalars
    from nupmpc.gp_problem import GpProblem
    from nupmpc.problem import Problem

_Builder = TypeVar("_Builder", bound="_Spec")


def _set(field: RepeatedScalars[float], values: Iterable[float]) -> None:
    del field[:]
    field.extend(values)


class _Spec:
    """What every builder shares: the spec, its dimensions and the JSON round trip."""

    def __init__(self, spec: pb.ProblemSpec) -> None:
        self._spec = spec

    @classmethod
    def _wrap(cls: type[_Builder], spec: pb.ProblemSpec) -> _Builder:
        """A builder holding `spec` itself (not a copy), without its constructor's checks."""
        self = cls.__new__(cls)
        _Spec.__init__(self, spec)
        return self

    @property
    def spec(self) -> pb.ProblemSpec:
        """A copy of the ProblemSpec built so far."""
        copy = pb.ProblemSpec()
        copy.CopyFrom(self._spec)
        return copy

    def to_json(self) -> str:
        """The spec in proto JSON, the form `nupmpc solve FILE` reads."""
        text: str = json_format.MessageToJson(self._spec, preserving_proto_field_name=True)
        return text

    @staticmethod
    def from_json(text: str) -> Problem | GpProblem:
        """A builder for a ProblemSpec in proto JSON (Problem or GpProblem)."""
        spec = pb.ProblemSpec()
        try:
            json_format.Parse(text, spec)
        except json_format.ParseError as error:
            raise ShapeError("json", f"not a ProblemSpec: {error}") from None
        return from_spec(spec)

    @staticmethod
    def from_spec(spec: pb.ProblemSpec) -> Problem | GpProblem:
        """Problem.from_spec(spec), GpProblem.from_spec(spec): the builder (Problem or
        GpProblem) holding a copy of `spec`."""
        return from_spec(spec)


def from_spec(spec: pb.ProblemSpec) -> Problem | GpProblem:
    """The builder (Problem or GpProblem) holding a copy of `spec`."""
    from nupmpc.gp_problem import GpProblem
    from nupmpc.problem import Problem
    copy = pb.ProblemSpec()
    copy.CopyFrom(spec)
    return GpProblem._wrap(copy) if copy.HasField("gp") else Problem._wrap(copy)
