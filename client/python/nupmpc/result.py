"""A SolveResult as numpy arrays."""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import FloatArray
from nupmpc.step import Dims


class PlanStatus(str, enum.Enum):
    """The SolveStatus of a result, without its prefix. A str: `plan.status == "CONVERGED"`
    holds, and it prints, formats and shows in containers as the string it equals."""

    UNSPECIFIED = "UNSPECIFIED"
    CONVERGED = "CONVERGED"
    ITERATION_LIMIT = "ITERATION_LIMIT"
    TIME_LIMIT = "TIME_LIMIT"
    NUMERICAL_ERROR = "NUMERICAL_ERROR"
    CANCELLED = "CANCELLED"
    SUPERSEDED = "SUPERSEDED"
    INFEASIBLE = "INFEASIBLE"
    HELD = "HELD"

    def __str__(self) -> str:
        return self.value

    def __repr__(self) -> str:
        return repr(self.value)

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)

    @classmethod
    def of(cls, status: pb.SolveStatus) -> PlanStatus:
        """The member of a SolveStatus number (ValueError for a number the stubs do not know)."""
        name: str = pb.SolveStatus.Name(status)
        return cls(name.replace("SOLVE_STATUS_", ""))


@dataclass(frozen=True, eq=False, repr=False)
class Plan:
    """One solve's answer.

    u (N, L), x (N+1, M), y (N+1, K) and u0 (L,) hold the plan when `has_plan` (apply u0
    only then: a result without a plan, e.g. SUPERSEDED or a time limit before any finite
    iterate, carries none and the arrays are empty). `held`: a session with a control
    period got no answer within the period (status HELD, no plan). `status` is the
    SolveStatus without its prefix (PlanStatus.CONVERGED, ..., equal to the strings
    "CONVERGED", ...); `solve_ms` the server's time in the solver, `round_trip_ms` the
    client's wall time of the call, a reconnect included (None for results not timed).
    `deadline` (steps with one: ProblemSpec.timing, Step.budget_ms) is "MET",
    "QUEUED_PAST_DEADLINE" or "SOLVE_TOO_LONG", with `deadline_slack_ms`; both None
    without one. `raw` is the SolveResult itself. Plans are immutable."""

    raw: pb.SolveResult
    status: PlanStatus
    has_plan: bool
    held: bool
    deadline: str | None
    deadline_slack_ms: float | None
    iterations: int
    objective: float
    max_violation: float
    solve_ms: float
    round_trip_ms: float | None
    warm_started: bool
    linearisations: int
    u: FloatArray
    x: FloatArray
    y: FloatArray
    output_stddev: FloatArray | None
    u0: FloatArray | None

    @classmethod
    def from_result(cls, result: pb.SolveResult, dims: Dims, round_trip_ms: float | None = None) -> Plan:
        """The Plan of a SolveResult of a problem of dimensions (M, L, K, N)."""
        M, L, K, N = dims
        deadline: str | None = (pb.DeadlineOutcome.Name(result.deadline).replace("DEADLINE_OUTCOME_", "")
                                if result.deadline else None)
        if result.has_plan:
            u = np.asarray(result.inputs, dtype=float).reshape(N, L)
            x = np.asarray(result.states, dtype=float).reshape(N + 1, M)
            y = np.asarray(result.outputs, dtype=float).reshape(N + 1, K)
            output_stddev = (np.asarray(result.output_stddev, dtype=float).reshape(N + 1, K)
                             if result.output_stddev else None)
            u0: FloatArray | None = u[0].copy()
        else:
            u, x, y = np.empty((0, L)), np.empty((0, M)), np.empty((0, K))
            output_stddev, u0 = None, None
        return cls(raw=result, status=PlanStatus.of(result.status), has_plan=result.has_plan,
                   held=result.status == pb.SOLVE_STATUS_HELD, deadline=deadline,
                   deadline_slack_ms=result.deadline_slack_ms if result.deadline else None,
                   iterations=result.iterations, objective=result.objective, max_violation=result.max_violation,
                   solve_ms=result.solve_ms, round_trip_ms=round_trip_ms, warm_started=result.warm_started,
                   linearisations=result.linearisations, u=u, x=x, y=y, output_stddev=output_stddev, u0=u0)

    @property
    def converged(self) -> bool:
        return self.status == PlanStatus.CONVERGED

    def __repr__(self) -> str:
        return (f"Plan(status={self.status}, objective={self.objective:.6g}, iterations={self.iterations}, "
                f"solve_ms={self.solve_ms:.3f}, has_plan={self.has_plan})")


def held_result() -> pb.SolveResult:
    """What a step whose period ended before its answer returns: status HELD, no plan."""
    return pb.SolveResult(status=pb.SOLVE_STATUS_HELD, has_plan=False, objective=float("nan"),
                          max_violation=float("nan"))
