"""nupmpc: Python client of the nupmpc MPC service (numpy in, numpy out).

    import nupmpc
    problem = nupmpc.Problem(A, B, C, horizon=30).input_box(-0.5, 0.5).output_weight(1.0)
    with nupmpc.connect("127.0.0.1:50051") as client:
        session = client.session(problem)
        plan = session.step(x)          # plan.u (N, L), plan.x (N+1, M), plan.y (N+1, K)
        plan = session.step(x, model=nupmpc.ModelUpdate(state_offset=d_hat))  # new model terms

Nonlinear plants: nupmpc.NonlinearModel(f, h) and nupmpc.NonlinearSession (real-time iteration).
"""

import pkgutil

# The generated stubs (nupmpc.v1) live in the build tree (build/python/nupmpc/v1), not
# beside this file: let the package span every `nupmpc` folder on sys.path.
__path__ = pkgutil.extend_path(__path__, __name__)

from nupmpc.errors import NupmpcError, ShapeError, error_from_code  # noqa: E402
from nupmpc.errors import (  # noqa: E402,F401
    InvalidArgument, NotFound, AlreadyExists, ResourceExhausted, Unavailable, Unauthenticated,
    PermissionDenied, DeadlineExceeded, Cancelled, FailedPrecondition, Internal)
from nupmpc.problem import Problem  # noqa: E402
from nupmpc.gp_problem import GpProblem  # noqa: E402
from nupmpc.regions import Ellipse, Rectangle  # noqa: E402
from nupmpc.result import Plan, PlanStatus  # noqa: E402
from nupmpc.reconnect import ReconnectOptions  # noqa: E402
from nupmpc.client import Client, connect  # noqa: E402
from nupmpc.session import Session  # noqa: E402
from nupmpc.instance import Instance, load_instance  # noqa: E402
from nupmpc.simulate import simulate, Trajectory  # noqa: E402
from nupmpc.model_update import ModelUpdate  # noqa: E402
from nupmpc.nonlinear import JacobianError, Linearisation, NonlinearModel, NonlinearSession, Period  # noqa: E402

__all__ = [
    "NupmpcError", "ShapeError", "error_from_code", "InvalidArgument", "NotFound", "AlreadyExists",
    "ResourceExhausted", "Unavailable", "Unauthenticated", "PermissionDenied", "DeadlineExceeded",
    "Cancelled", "FailedPrecondition", "Internal", "Problem", "GpProblem", "Ellipse", "Rectangle",
    "Plan", "PlanStatus", "ReconnectOptions", "Client", "connect", "Session", "Instance", "load_instance",
    "simulate", "Trajectory", "aio", "ModelUpdate", "NonlinearModel", "NonlinearSession", "JacobianError",
    "Linearisation", "Period",
]
from nupmpc import aio  # noqa: E402,F401  (nupmpc.aio.connect: the asyncio variant)
