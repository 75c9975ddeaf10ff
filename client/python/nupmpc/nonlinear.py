"""Nonlinear MPC on the linear service: real-time iteration (RTI) over Step.model.

A discrete-time plant x[n+1] = f(x[n], u[n]), y[n] = h(x[n]) is linearised along a
trajectory (x̄, ū) into the time-varying model the server solves,

    A[n] = ∂f/∂x, B[n] = ∂f/∂u, c[n] = f(x̄[n], ū[n]) - A[n] x̄[n] - B[n] ū[n]   (n < N)
    C[n] = ∂h/∂x, d[n] = h(x̄[n]) - C[n] x̄[n]                                     (n ≤ N)

and each period sends ONE step: the measured state and this model, linearised along the
previous plan shifted by one step (the warm start shifted with it). With iterations > 1
the period re-linearises along the new plan and re-solves (warm start "keep"), SQP-style,
until the plan moves less than `tolerance`. These iterations are Gauss-Newton (the model's
curvature is not in the cost): they converge fast where the plan's multipliers are small
and linearly, or not at all with full steps, where they are large; the step towards each
new plan is halved while the plan moves no less than before, which stops two
linearisations from sending the plan back and forth between them.

    model = nupmpc.NonlinearModel(f, h, f_x=..., f_u=..., h_x=...)  # or finite differences
    problem = model.problem(x0, u0, horizon=30).input_box(-1, 1).output_weight(1.0, ref)
    with nupmpc.NonlinearSession(client, problem, model) as session:
        plan = session.step(x)       # plan.u0 to apply; session.periods[-1]: what it took
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, Callable, Iterable, Optional

import numpy as np

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, FloatArray, as_array, finite, vector
from nupmpc.client import ProblemLike, spec_of
from nupmpc.errors import ShapeError
from nupmpc.model_update import ModelUpdate, refuse_model_update
from nupmpc.result import Plan, PlanStatus
from nupmpc.spec_builder import _set
from nupmpc.step import WarmStart, dims_of

if TYPE_CHECKING:
    from nupmpc._proto import RepeatedMessages
    from nupmpc.client import Client
    from nupmpc.problem import Problem
    from nupmpc.reconnect import ReconnectOptions
    from nupmpc.session import Session

# The plant's functions, numpy in: f(x, u) → next x, h(x) → y, and their Jacobians.
StateFunction = Callable[[FloatArray, FloatArray], ArrayLike]
OutputFunction = Callable[[FloatArray], ArrayLike]

# Central differences: truncation error ~ h², rounding ~ eps/h; balanced at h ~ eps^(1/3).
FD_STEP = 6e-6


class JacobianError(ShapeError):
    """A given Jacobian that disagrees with central finite differences. `argument` names it
    ("f_x", "f_u" or "h_x"), `entry` is its (row, column), `given` and `estimated` the two
    values, `x` and `u` the point (u None for h_x)."""

    def __init__(self, argument: str, entry: tuple[int, int], given: float, estimated: float, x: ArrayLike,
                 u: ArrayLike | None = None) -> None:
        self.entry, self.given, self.estimated, self.x, self.u = entry, given, estimated, x, u
        at = f"x = {np.array2string(np.asarray(x), precision=4)}" + (
            "" if u is None else f", u = {np.array2string(np.asarray(u), precision=4)}")
        super().__init__(argument, f"entry [{entry[0]}, {entry[1]}] is {given:.6g}, central differences give "
                                   f"{estimated:.6g} (at {at})")


@dataclass
class Linearisation:
    """The time-varying model along a trajectory: A (N, M, M), B (N, M, L), c (N, M),
    C (N+1, K, M), d (N+1, K)."""
    A: FloatArray
    B: FloatArray
    c: FloatArray
    C: FloatArray
    d: FloatArray

    def model_update(self) -> ModelUpdate:
        """The ModelUpdate replacing every model term of a session."""
        K = self.C.shape[1]
        return ModelUpdate(A=self.A, B=self.B, state_offset=self.c, C=self.C if K else None,
                           output_offset=self.d if K else None)


class NonlinearModel:
    """x[n+1] = f(x, u), y = h(x) (numpy in, numpy out; h None: no outputs). The Jacobians
    f_x(x, u) (M, M), f_u(x, u) (M, L), h_x(x) (K, M) are callables or, when None, central
    finite differences with relative step `fd_step`."""

    def __init__(self, f: StateFunction, h: Optional[OutputFunction] = None, f_x: Optional[StateFunction] = None,
                 f_u: Optional[StateFunction] = None, h_x: Optional[OutputFunction] = None,
                 fd_step: float = FD_STEP) -> None:
        for name, value in (("f", f), ("h", h), ("f_x", f_x), ("f_u", f_u), ("h_x", h_x)):
            if value is not None and not callable(value):
                raise ShapeError(name, f"expected a callable, got {type(value).__name__}")
        if not callable(f):
            raise ShapeError("f", "expected a callable (x, u) -> next x")
        if h is None and h_x is not None:
            raise ShapeError("h_x", "given without h")
        if not fd_step > 0:
            raise ShapeError("fd_step", f"must be > 0, got {fd_step!r}")
        self.f, self.h, self.f_x, self.f_u, self.h_x, self.fd_step = f, h, f_x, f_u, h_x, fd_step

    # Evaluations, checked.
    def next_state(self, x: FloatArray, u: FloatArray) -> FloatArray:
        x_next = np.asarray(self.f(x, u), dtype=float)
        if x_next.shape != np.shape(x):
            raise ShapeError("f", f"returned shape {x_next.shape} for a state of shape {np.shape(x)}")
        return x_next

    def output(self, x: FloatArray) -> FloatArray:
        if self.h is None:
            return np.zeros(0)
        y: FloatArray = np.atleast_1d(np.asarray(self.h(x), dtype=float))
        if y.ndim != 1:
            raise ShapeError("h", f"returned shape {y.shape}, expected a vector")
        return y

    def rollout(self, x0: ArrayLike, u: FloatArray) -> FloatArray:
        """The states x[0..N] from x0 under the inputs u (N, L)."""
        xs = [np.asarray(x0, dtype=float)]
        for u_n in u:
            xs.append(self.next_state(xs[-1], u_n))
        states: FloatArray = np.array(xs)
        return states

    # Jacobians.
    def _differences(self, g: Callable[[FloatArray], FloatArray], v: FloatArray, rows: int) -> FloatArray:
        J = np.empty((rows, len(v)))
        for j in range(len(v)):
            h = self.fd_step * max(1.0, abs(v[j]))
            plus, minus = v.copy(), v.copy()
            plus[j] += h
            minus[j] -= h
            J[:, j] = (g(plus) - g(minus)) / (plus[j] - minus[j])
        return J

    def fd_jacobians(self, x: ArrayLike, u: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(∂f/∂x, ∂f/∂u, ∂h/∂x) at (x, u) by central differences."""
        at_x, at_u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        return (self._differences(lambda v: self.next_state(v, at_u), at_x, len(at_x)),
                self._differences(lambda v: self.next_state(at_x, v), at_u, len(at_x)),
                self._differences(self.output, at_x, len(self.output(at_x))))

    def state_jacobians(self, x: ArrayLike, u: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(∂f/∂x, ∂f/∂u) at (x, u): the given callables, else central differences."""
        at_x, at_u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        M, L = len(at_x), len(at_u)
        A = (self._differences(lambda v: self.next_state(v, at_u), at_x, M) if self.f_x is None else
             self._given("f_x", self.f_x(at_x, at_u), M, M))
        B = (self._differences(lambda v: self.next_state(at_x, v), at_u, M) if self.f_u is None else
             self._given("f_u", self.f_u(at_x, at_u), M, L))
        return A, B

    def output_jacobian(self, x: ArrayLike) -> FloatArray:
        """∂h/∂x at x (K, M): the given callable, else central differences."""
        x = np.asarray(x, dtype=float)
        K = len(self.output(x))
        if not K:
            return np.zeros((0, len(x)))
        return self._differences(self.output, x, K) if self.h_x is None else self._given("h_x", self.h_x(x), K, len(x))

    def jacobians(self, x: ArrayLike, u: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(∂f/∂x, ∂f/∂u, ∂h/∂x) at (x, u): the given callables, else central differences."""
        return (*self.state_jacobians(x, u), self.output_jacobian(x))

    @staticmethod
    def _given(name: str, value: ArrayLike, rows: int, cols: int) -> FloatArray:
        array = as_array(value, name, ndim_max=2)
        if array.ndim < 2 and (rows == 1 or cols == 1):
            array = array.reshape(rows, cols)
        if array.shape != (rows, cols):
            raise ShapeError(name, f"returned shape {array.shape}, expected ({rows}, {cols})")
        return array

    def check_jacobians(self, points: Iterable[tuple[ArrayLike, ArrayLike]], tolerance: float = 1e-5) -> None:
        """Compares the given Jacobians with central differences at each (x, u) of `points`;
        raises JacobianError for the first entry off by more than tolerance·(1 + the largest
        magnitude in its row of the estimate)."""
        for x, u in points:
            x = np.asarray(x, dtype=float)
            u = np.asarray(u, dtype=float)
            A, B, C = self.jacobians(x, u)
            A_fd, B_fd, C_fd = self.fd_jacobians(x, u)
            for name, given, estimate, at_u in (("f_x", A, A_fd, u), ("f_u", B, B_fd, u), ("h_x", C, C_fd, None)):
                if getattr(self, name) is None or estimate.size == 0:
                    continue
                scale = 1.0 + np.abs(estimate).max(axis=1, keepdims=True)
                bad = np.argwhere(~(np.abs(given - estimate) <= tolerance * scale))
                if len(bad):
                    i, j = bad[0]
                    raise JacobianError(name, (int(i), int(j)), float(given[i, j]), float(estimate[i, j]), x, at_u)

    def linearise(self, x_bar: FloatArray, u_bar: FloatArray) -> Linearisation:
        """The Linearisation along states x̄ (N+1, M) and inputs ū (N, L)."""
        N = len(u_bar)
        A, B, c, C, d = [], [], [], [], []
        for n in range(N + 1):
            x = np.asarray(x_bar[n], dtype=float)
            C_n = self.output_jacobian(x)
            C.append(C_n)
            d.append(self.output(x) - C_n @ x)
            if n < N:
                u = np.asarray(u_bar[n], dtype=float)
                A_n, B_n = self.state_jacobians(x, u)
                A.append(A_n)
                B.append(B_n)
                c.append(self.next_state(x, u) - A_n @ x - B_n @ u)
        return Linearisation(np.array(A), np.array(B), np.array(c), np.array(C), np.array(d))

    def problem(self, x0: ArrayLike, u0: ArrayLike, horizon: int) -> Problem:
        """A nupmpc.Problem template with this model linearised at (x0, u0) (time-invariant),
        to chain priors, bounds and costs on; NonlinearSession fills in the model."""
        from nupmpc.problem import Problem
        x0 = finite(as_array(x0, "x0", ndim_max=1), "x0")
        u0 = finite(as_array(u0, "u0", ndim_max=1), "u0")
        if x0.ndim != 1 or u0.ndim != 1:
            raise ShapeError("x0" if x0.ndim != 1 else "u0", "expected a vector")
        A, B, C = self.jacobians(x0, u0)
        c = self.next_state(x0, u0) - A @ x0 - B @ u0
        K = len(C)
        return Problem(A, B, C if K else None, horizon=horizon, x0=x0, state_offset=c,
                       output_offset=(self.output(x0) - C @ x0) if K else None)


@dataclass
class Period:
    """What one NonlinearSession.step took: `linearisations` (models sent), `passes` (the
    solver's iterations over all of its solves), `time_ms` (the client's wall time: the
    linearisations and the round trips), `solve_ms` (the server's time in the solver),
    `moved` (how far the last plan moved from the trajectory it was linearised along:
    relative max-norm of states and inputs), `status` of the last solve."""
    linearisations: int
    passes: int
    time_ms: float
    solve_ms: float
    moved: float
    status: PlanStatus


def _moved(x_new: FloatArray, u_new: FloatArray, x_old: FloatArray, u_old: FloatArray) -> float:
    dx = np.abs(x_new - x_old).max() / max(1.0, np.abs(x_old).max())
    du = np.abs(u_new - u_old).max() / max(1.0, np.abs(u_old).max()) if u_old.size else 0.0
    return float(max(dx, du))


class NonlinearSession:
    """A session on a nonlinear plant: each step(x) linearises `model` along the previous
    plan shifted by one step, sends one Step with x and the whole time-varying model, and
    returns its Plan.

    problem: the template (nupmpc.Problem or ProblemSpec) whose priors, bounds, costs,
      horizon and options are used; its model is replaced by `model` linearised along the
      initial guess from its initial state (one matrix per step, so that later updates keep
      the warm start).
    u_guess: the initial input guess, (L,) or (N, L) (default zeros); x_guess: (N+1, M)
      states to linearise along for the first period (default: the rollout of u_guess).
    iterations: linearisations per period (1: RTI; k > 1: up to k, re-solved with warm start
      "keep" until the plan moves less than `tolerance`, relative max-norm; see the module
      text for the step rule).
    check_jacobians: compare given Jacobians with central differences along the initial
      guess and at points near it (JacobianError naming the Jacobian and the entry).
    period: the control period in seconds (None: none): step() returns by it, with the plan
      of the last linearisation answered in time, or held (plan.held) when the first was not
      (nupmpc.Session)."""

    def __init__(self, client: Client, problem: ProblemLike, model: NonlinearModel, u_guess: ArrayLike | None = None,
                 x_guess: ArrayLike | None = None, iterations: int = 1, tolerance: float = 1e-6,
                 check_jacobians: bool = True, jacobian_tolerance: float = 1e-5,
                 reconnect: ReconnectOptions | None = None, period: float | None = None) -> None:
        if not isinstance(model, NonlinearModel):
            raise ShapeError("model", f"expected a nupmpc.NonlinearModel, got {type(model).__name__}")
        spec = pb.ProblemSpec()
        spec.CopyFrom(spec_of(problem))
        refuse_model_update(spec)
        if spec.initial_state.HasField("covariance"):
            raise ShapeError("problem", "a NonlinearSession needs a fixed initial state (no covariance)")
        M, L, K, N = self.dims = dims_of(spec)
        if int(iterations) != iterations or iterations < 1:
            raise ShapeError("iterations", f"must be an integer ≥ 1, got {iterations!r}")
        self.model, self.iterations, self.tolerance = model, int(iterations), float(tolerance)
        self._u_guess = self._inputs(u_guess, "u_guess")
        x0 = np.asarray(spec.initial_state.mean, dtype=float)
        if x_guess is not None:
            x_guess = finite(as_array(x_guess, "x_guess", ndim_max=2), "x_guess")
            if x_guess.shape != (N + 1, M):
                raise ShapeError("x_guess", f"expected shape ({N + 1}, {M}), got {x_guess.shape}")
        self._x_guess = x_guess
        x_bar = self._first_states(x0)
        if x_bar.shape != (N + 1, M):
            raise ShapeError("f", f"returned states of shape {x_bar.shape[1:]}, the problem has {M} states")
        y = model.output(x0)
        if len(y) != K:
            raise ShapeError("h", f"returned {len(y)} outputs, the problem has {K}")
        if check_jacobians:
            rng = np.random.default_rng(0)
            points = list(zip(x_bar[:N], self._u_guess))
            points += [(x + 0.1 * (1 + np.abs(x)) * rng.standard_normal(M),
                        u + 0.1 * (1 + np.abs(u)) * rng.standard_normal(L)) for x, u in points]
            model.check_jacobians(points, jacobian_tolerance)
        _fill_model(spec, model.linearise(x_bar, self._u_guess))
        self.session: Session = client.session(spec, reconnect, period=period)
        self.periods: list[Period] = []
        self._plan: tuple[FloatArray, FloatArray] | None = None  # the last plan with has_plan: (states, inputs)

    def _inputs(self, value: ArrayLike | None, name: str) -> FloatArray:
        M, L, K, N = self.dims
        if value is None:
            return np.zeros((N, L))
        array = finite(as_array(value, name, ndim_max=2), name)
        if array.ndim < 2:
            return np.tile(vector(array, name, L), (N, 1))
        if array.shape != (N, L):
            raise ShapeError(name, f"expected shape ({L},) or ({N}, {L}), got {array.shape}")
        return array.copy()

    def _first_states(self, x: FloatArray) -> FloatArray:
        if self._x_guess is not None:
            x_bar = self._x_guess.copy()
            x_bar[0] = x
            return x_bar
        return self.model.rollout(x, self._u_guess)

    @property
    def spec(self) -> pb.ProblemSpec:
        """The spec the session would be re-created from (its model: the last one sent)."""
        return self.session.spec

    @property
    def reconnects(self) -> int:
        return self.session.reconnects

    def _trajectory(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(x̄, ū) for this period: the previous plan one step on (its last input repeated,
        the last state extended by f), with x̄[0] the measured state; the guess at first."""
        if self._plan is None:
            return self._first_states(x), self._u_guess.copy()
        states, inputs = self._plan
        u_bar = np.vstack([inputs[1:], inputs[-1:]])
        x_bar = np.vstack([states[1:], self.model.next_state(states[-1], inputs[-1])[None, :]])
        x_bar[0] = x
        return x_bar, u_bar

    def step(self, x: ArrayLike, *, iterations: int | None = None, tolerance: float | None = None,
             warm_start: WarmStart = None, **step_args: Any) -> Plan:
        """One period for the measured state x (M,): returns the Plan (apply plan.u0) and
        appends a Period to `periods`. step_args (references, bounds, shift, ...) go with
        the first solve of the period as in Session.step; iterations and tolerance
        override the session's for this period."""
        M, L, K, N = self.dims
        x = finite(vector(x, "x", M), "x")
        iterations = self.iterations if iterations is None else int(iterations)
        tolerance = self.tolerance if tolerance is None else float(tolerance)
        start = time.perf_counter()
        # With a period, every linearisation of this period shares its deadline.
        deadline = time.monotonic() + self.session.period if self.session.period else None
        x_bar, u_bar = self._trajectory(x)
        passes, solve_ms, moved, plan, step = 0, 0.0, np.inf, None, 1.0
        for k in range(iterations):
            update = self.model.linearise(x_bar, u_bar).model_update()
            if k == 0:
                plan = self.session.step(x, model=update, warm_start=warm_start, deadline=deadline, **step_args)
            else:
                refined = self.session.step(x, model=update, warm_start="keep", deadline=deadline)
                if refined.held:
                    break  # the period is over: the previous linearisation's plan is this state's
                plan = refined
            passes += plan.iterations
            solve_ms += plan.solve_ms
            if not plan.has_plan:
                break
            last, moved = moved, _moved(plan.x, plan.u, x_bar, u_bar)
            if moved < tolerance:
                break
            # Full steps, halved while the plan moves no less than before (a linearisation
            # can send the plan back and forth between two trajectories).
            if moved >= last:
                step *= 0.5
            elif moved < 0.5 * last:
                step = min(1.0, 2.0 * step)
            x_bar, u_bar = x_bar + step * (plan.x - x_bar), u_bar + step * (plan.u - u_bar)
        if plan is None:  # no linearisation ran
            raise ShapeError("iterations", f"must be an integer ≥ 1, got {iterations!r}")
        if plan.has_plan:
            self._plan = (plan.x.copy(), plan.u.copy())
        elif self._plan is not None:
            # No plan: the next period shifts the trajectory this one was linearised along.
            self._plan = (x_bar, u_bar)
        self.periods.append(Period(linearisations=k + 1, passes=passes, time_ms=(time.perf_counter() - start) * 1e3,
                                   solve_ms=solve_ms, moved=moved, status=plan.status))
        return plan

    def close(self) -> None:
        self.session.close()

    def __enter__(self) -> NonlinearSession:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def _fill_model(spec: pb.ProblemSpec, lin: Linearisation) -> None:
    """Writes a Linearisation into spec.model, one matrix per step."""
    m = spec.model
    terms: list[tuple[RepeatedMessages[pb.Matrix], Iterable[FloatArray]]] = [
        (m.a, lin.A), (m.b, lin.B), (m.c, lin.C if m.num_outputs else lin.C[:0])]
    for field, arrays in terms:
        del field[:]
        for a in arrays:
            field.add(rows=a.shape[0], cols=a.shape[1], data=a.ravel().tolist())
    _set(m.state_offset, lin.c.ravel().tolist())
    _set(m.output_offset, lin.d.ravel().tolist() if m.num_outputs else [])
