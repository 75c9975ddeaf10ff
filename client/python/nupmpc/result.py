"""A SolveResult as numpy arrays."""

import numpy as np

from nupmpc._proto import pb


class Plan:
    """One solve's answer.

    u (N, L), x (N+1, M), y (N+1, K) and u0 (L,) hold the plan when `has_plan` (apply u0
    only then: a result without a plan, e.g. SUPERSEDED or a time limit before any finite
    iterate, carries none and the arrays are empty). `held`: a session with a control
    period got no answer within the period (status "HELD", no plan). `status` is the SolveStatus name
    without its prefix ("CONVERGED", ...); `solve_ms` the server's time in the solver,
    `round_trip_ms` the client's wall time of the call, a reconnect included (None for
    results not timed)."""

    def __init__(self, result, dims, round_trip_ms=None):
        M, L, K, N = dims
        self.raw = result
        self.status = pb.SolveStatus.Name(result.status).replace("SOLVE_STATUS_", "")
        self.has_plan = result.has_plan
        self.held = result.status == pb.SOLVE_STATUS_HELD
        # Steps with a deadline (ProblemSpec.timing, Step.budget_ms): "MET",
        # "QUEUED_PAST_DEADLINE" or "SOLVE_TOO_LONG", and the slack; None without one.
        self.deadline = (pb.DeadlineOutcome.Name(result.deadline).replace("DEADLINE_OUTCOME_", "")
                         if result.deadline else None)
        self.deadline_slack_ms = result.deadline_slack_ms if result.deadline else None
        self.iterations = result.iterations
        self.objective = result.objective
        self.max_violation = result.max_violation
        self.solve_ms = result.solve_ms
        self.round_trip_ms = round_trip_ms
        self.warm_started = result.warm_started
        self.linearisations = result.linearisations
        if result.has_plan:
            self.u = np.asarray(result.inputs, dtype=float).reshape(N, L)
            self.x = np.asarray(result.states, dtype=float).reshape(N + 1, M)
            self.y = np.asarray(result.outputs, dtype=float).reshape(N + 1, K)
            self.output_stddev = (np.asarray(result.output_stddev, dtype=float).reshape(N + 1, K)
                                  if result.output_stddev else None)
            self.u0 = self.u[0].copy()
        else:
            self.u, self.x, self.y = np.empty((0, L)), np.empty((0, M)), np.empty((0, K))
            self.output_stddev, self.u0 = None, None

    @property
    def converged(self):
        return self.status == "CONVERGED"

    def __repr__(self):
        return (f"Plan(status={self.status}, objective={self.objective:.6g}, iterations={self.iterations}, "
                f"solve_ms={self.solve_ms:.3f}, has_plan={self.has_plan})")


def held_result():
    """What a step whose period ended before its answer returns: status HELD, no plan."""
    return pb.SolveResult(status=pb.SOLVE_STATUS_HELD, has_plan=False, objective=float("nan"),
                          max_violation=float("nan"))
