"""The generated nupmpc.v1 messages and service stub.

They are generated at build time (CMake target ``nupmpc_python``, or ``pip install``) and
never committed, so this module turns a missing stub into an error that says how to make it.
Type checkers read the messages' types from the nupmpc_pb2.pyi that protoc writes beside them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

try:
    from nupmpc.v1 import nupmpc_pb2 as pb
    from nupmpc.v1 import nupmpc_pb2_grpc as pb_grpc
except ImportError as error:  # pragma: no cover - the message is the point
    raise ImportError(
        "nupmpc: the generated stubs nupmpc.v1.nupmpc_pb2 are missing. Build them with "
        "`cmake --build build --target nupmpc_python` and put build/python on PYTHONPATH "
        "next to client/python (or `pip install client/python`)") from error

if TYPE_CHECKING:
    # The repeated fields of the messages, for annotations only (protobuf's own classes).
    from google.protobuf.internal.containers import RepeatedCompositeFieldContainer as RepeatedMessages
    from google.protobuf.internal.containers import RepeatedScalarFieldContainer as RepeatedScalars

__all__ = ["pb", "pb_grpc"]
if TYPE_CHECKING:
    __all__ += ["RepeatedMessages", "RepeatedScalars"]
