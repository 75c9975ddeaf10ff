"""Typed errors: one exception class per gRPC status code, carrying the code and the field
the server named, and ShapeError for arguments refused before anything is sent."""

from __future__ import annotations

import re
from typing import Protocol

import grpc

# The server starts a message with the field it refuses: "FIELD: rule", "FIELD at step n:
# ...", "FIELD = value: ...", "FIELD (note): ..." (e.g. "spec.input_priors[1] at step 0:
# lower = 1 must be < upper = 0.5"); a field path is a dotted identifier with [index] parts.
_FIELD = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*(?:\[\d+\])*(?:\.[A-Za-z_][A-Za-z0-9_]*(?:\[\d+\])*)*)"
                    r"(?=:|\s+at\s|\s*=\s|\s+\()")


def field_of(message: str | None) -> str | None:
    """The field a server message names at its start ("spec.model.a[0]: ..."), or None."""
    match = _FIELD.match(message or "")
    return match.group(1) if match else None


class NupmpcError(Exception):
    """An error from the server (or the transport): `code` is the grpc.StatusCode, `field`
    the field the message names (None when it names none), `details` the server's text."""

    code: grpc.StatusCode = grpc.StatusCode.UNKNOWN

    def __init__(self, details: str, code: grpc.StatusCode | None = None, field: str | None = None) -> None:
        if code is not None:
            self.code = code
        self.details = details
        self.field = field if field is not None else field_of(details)
        super().__init__(f"{self.code.name}: {details}")


class InvalidArgument(NupmpcError):
    code = grpc.StatusCode.INVALID_ARGUMENT


class NotFound(NupmpcError):
    code = grpc.StatusCode.NOT_FOUND


class AlreadyExists(NupmpcError):
    code = grpc.StatusCode.ALREADY_EXISTS


class ResourceExhausted(NupmpcError):
    code = grpc.StatusCode.RESOURCE_EXHAUSTED


class FailedPrecondition(NupmpcError):
    code = grpc.StatusCode.FAILED_PRECONDITION


class Unavailable(NupmpcError):
    code = grpc.StatusCode.UNAVAILABLE


class Unauthenticated(NupmpcError):
    code = grpc.StatusCode.UNAUTHENTICATED


class PermissionDenied(NupmpcError):
    code = grpc.StatusCode.PERMISSION_DENIED


class DeadlineExceeded(NupmpcError):
    code = grpc.StatusCode.DEADLINE_EXCEEDED


class Cancelled(NupmpcError):
    code = grpc.StatusCode.CANCELLED


class Internal(NupmpcError):
    code = grpc.StatusCode.INTERNAL


_BY_CODE: dict[grpc.StatusCode, type[NupmpcError]] = {cls.code: cls for cls in (
    InvalidArgument, NotFound, AlreadyExists, ResourceExhausted, FailedPrecondition, Unavailable,
    Unauthenticated, PermissionDenied, DeadlineExceeded, Cancelled, Internal)}
# ControlResponse.error_code is a google.rpc.Code number; grpc.StatusCode values are (number, name).
_BY_NUMBER: dict[int, grpc.StatusCode] = {code.value[0]: code for code in grpc.StatusCode}


def error_from_code(code: grpc.StatusCode | int, details: str) -> NupmpcError:
    """The typed exception for `code` (a grpc.StatusCode or its number) and `details`."""
    if isinstance(code, int):
        code = _BY_NUMBER.get(code, grpc.StatusCode.UNKNOWN)
    cls = _BY_CODE.get(code, NupmpcError)
    return cls(details, code=code)


class CallStatus(Protocol):
    """How a finished call reports its status (a grpc.RpcError, a grpc.aio call)."""

    def code(self) -> grpc.StatusCode: ...

    def details(self) -> str | None: ...


def error_from_rpc(error: CallStatus) -> NupmpcError:
    """The typed exception for a grpc.RpcError (a failed call)."""
    return error_from_code(error.code(), error.details() or "")


class ShapeError(ValueError):
    """An argument of the wrong shape or value, refused before anything is sent;
    `argument` names it (e.g. "A", "references", "input_box.lower")."""

    def __init__(self, argument: str, message: str) -> None:
        self.argument = argument
        super().__init__(f"{argument}: {message}")
