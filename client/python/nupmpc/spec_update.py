"""What an answered Step leaves in the server's session, written back into the spec the
session was created from, so that a session re-created after a server restart is the
session the server had, not the one it started with.

A line-by-line mirror of the C++ client's client/spec_update.cc (ApplyStepToSpec), itself
the mirror of the server's step semantics: change one, change all. The model update
(Step.model, apply_model_update) mirrors the server's WriteModelChanges
(core/session/model_update.cc), including the storage it leaves: a time-invariant matrix
given for some steps becomes N (C: N + 1) matrices in the spec, as in the session.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterable

from nupmpc._proto import pb

if TYPE_CHECKING:
    from nupmpc._proto import RepeatedMessages, RepeatedScalars

_PER_STEP = ("weight", "target", "lower", "upper", "slope", "radius", "exponent")


def shift_components(components: Iterable[pb.ComponentPrior]) -> None:
    """Every per-step array one step earlier (n+1 → n, the last kept; length 1: constant)."""
    for prior in components:
        for name in _PER_STEP:
            values = getattr(prior, name)
            for n in range(len(values) - 1):
                values[n] = values[n + 1]


def _replace(entries: Iterable[pb.PriorUpdate.Entry], components: RepeatedMessages[pb.ComponentPrior]) -> None:
    for entry in entries:
        # The server refuses a step with an index out of range, so an accepted one has none.
        if entry.index < len(components):
            components[entry.index].CopyFrom(entry.prior)


def _shift_steps(items: RepeatedMessages[pb.Matrix]) -> None:
    """Step n+1 becomes step n, the last step repeated (a no-op on one item)."""
    for n in range(len(items) - 1):
        items[n].CopyFrom(items[n + 1])


def _shift_rows(values: RepeatedScalars[float], width: int) -> None:
    """The same on a flat step-major array of `width` values per step."""
    for i in range(len(values) - width):
        values[i] = values[i + width]


def _write_all_steps(values: Iterable[float], field: RepeatedScalars[float], width: int, steps: int) -> None:
    """An all-step offset: `width` values keep per-step storage per step (the same at every
    step), else replace; steps·width values replace."""
    given = list(values)
    if len(given) == width and len(field) == width * steps:
        given = given * steps
    del field[:]
    field.extend(given)


def _write_matrices(entries: RepeatedMessages[pb.ModelUpdate.MatrixAt], field: RepeatedMessages[pb.Matrix],
                    steps: int, rows: int, cols: int) -> None:
    if not entries:
        return
    if len(field) != steps:
        first = pb.Matrix()
        if len(field):
            first.CopyFrom(field[0])
        else:
            first.rows, first.cols = rows, cols
            first.data.extend([0.0] * (rows * cols))
        del field[:]
        for _ in range(steps):
            field.add().CopyFrom(first)
    for entry in entries:
        field[entry.step].CopyFrom(entry.matrix)


def _write_vectors(entries: RepeatedMessages[pb.ModelUpdate.VectorAt], field: RepeatedScalars[float], steps: int,
                   width: int) -> None:
    if not entries:
        return
    if len(field) != steps * width:
        first = list(field[:width]) if len(field) else [0.0] * width
        del field[:]
        field.extend(first * steps)
    for entry in entries:
        for i, v in enumerate(entry.values):
            field[entry.step * width + i] = v


def apply_model_update(update: pb.ModelUpdate, spec: pb.ProblemSpec) -> None:
    """Writes an accepted pb.ModelUpdate into `spec`'s model as the server does: shift, then
    the all-step offsets, then the single steps."""
    m = spec.model
    M, K, N = m.num_states, m.num_outputs, m.horizon
    if update.shift:
        for field in (m.a, m.b, m.c):
            _shift_steps(field)
        if len(m.state_offset) == N * M:
            _shift_rows(m.state_offset, M)
        if len(m.output_offset) == (N + 1) * K:
            _shift_rows(m.output_offset, K)
    if update.state_offsets:
        _write_all_steps(update.state_offsets, m.state_offset, M, N)
    if update.output_offsets:
        _write_all_steps(update.output_offsets, m.output_offset, K, N + 1)
    _write_matrices(update.a, m.a, N, M, M)
    _write_matrices(update.b, m.b, N, M, m.num_inputs)
    _write_matrices(update.c, m.c, N + 1, K, M)
    _write_vectors(update.state_offset, m.state_offset, N, M)
    _write_vectors(update.output_offset, m.output_offset, N + 1, K)


def apply_step_to_spec(step: pb.Step, result: pb.SolveResult, spec: pb.ProblemSpec) -> None:
    """Applies `step`, answered with `result` (an answer, not an error), to `spec`."""
    if result.status == pb.SOLVE_STATUS_SUPERSEDED:
        return  # nothing of it was applied
    if step.state:
        del spec.initial_state.mean[:]
        spec.initial_state.mean.extend(step.state)
    if spec.HasField("gp"):
        # A GP session refuses step.update; its reference is replaced as a whole.
        if step.reference:
            del spec.gp.reference[:]
            spec.gp.reference.extend(step.reference)
        return
    if step.HasField("update"):
        update = step.update
        if update.shift:
            shift_components(spec.input_priors)
            shift_components(spec.output_priors)
            # Δu sessions: the difference priors are the server's input priors, shifted with them.
            if spec.HasField("input_differences"):
                shift_components(spec.input_differences.priors)
        _replace(update.inputs, spec.input_priors)
        _replace(update.outputs, spec.output_priors)
    if step.HasField("model"):
        apply_model_update(step.model, spec)
    # Δu sessions: the server carries the plan's u[0] as u[-1] of the next step; a step's
    # own previous_input is for that step only; a result without a plan leaves it.
    L = spec.model.num_inputs
    if spec.HasField("input_differences") and result.has_plan and len(result.inputs) >= L:
        previous = spec.input_differences.previous_input
        del previous[:]
        previous.extend(result.inputs[:L])
