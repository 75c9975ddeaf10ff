"""What every spec builder (Problem, GpProblem) shares: the ProblemSpec it writes, a copy
of it, and the round trip through the proto JSON that `nupmpc solve FILE` reads."""

from google.protobuf import json_format

from nupmpc._proto import pb
from nupmpc.errors import ShapeError


def _set(field, values):
    del field[:]
    field.extend(values)


class _Spec:
    """What every builder shares: the spec, its dimensions and the JSON round trip."""

    def __init__(self, spec):
        self._spec = spec

    @property
    def spec(self):
        """A copy of the ProblemSpec built so far."""
        copy = pb.ProblemSpec()
        copy.CopyFrom(self._spec)
        return copy

    def to_json(self):
        """The spec in proto JSON, the form `nupmpc solve FILE` reads."""
        return json_format.MessageToJson(self._spec, preserving_proto_field_name=True)

    @staticmethod
    def from_json(text):
        """A builder for a ProblemSpec in proto JSON (Problem or GpProblem)."""
        spec = pb.ProblemSpec()
        try:
            json_format.Parse(text, spec)
        except json_format.ParseError as error:
            raise ShapeError("json", f"not a ProblemSpec: {error}") from None
        return from_spec(spec)


def from_spec(spec):
    """The builder (Problem or GpProblem) holding a copy of `spec`."""
    from nupmpc.gp_problem import GpProblem
    from nupmpc.problem import Problem
    copy = pb.ProblemSpec()
    copy.CopyFrom(spec)
    return GpProblem._wrap(copy) if copy.HasField("gp") else Problem._wrap(copy)


# Problem.from_spec(spec), GpProblem.from_spec(spec): the same dispatch.
_Spec.from_spec = staticmethod(from_spec)
