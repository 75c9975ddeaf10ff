"""What an answered Step leaves in the server's session, written back into the spec the
session was created from, so that a session re-created after a server restart is the
session the server had, not the one it started with.

A line-by-line mirror of the C++ client's client/spec_update.cc (ApplyStepToSpec), itself
the mirror of the server's step semantics: change one, change all.
"""

from nupmpc._proto import pb

_PER_STEP = ("weight", "target", "lower", "upper", "slope", "radius", "exponent")


def shift_components(components):
    """Every per-step array one step earlier (n+1 → n, the last kept; length 1: constant)."""
    for prior in components:
        for name in _PER_STEP:
            values = getattr(prior, name)
            for n in range(len(values) - 1):
                values[n] = values[n + 1]


def _replace(entries, components):
    for entry in entries:
        # The server refuses a step with an index out of range, so an accepted one has none.
        if entry.index < len(components):
            components[entry.index].CopyFrom(entry.prior)


def apply_step_to_spec(step, result, spec):
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
    # Δu sessions: the server carries the plan's u[0] as u[-1] of the next step; a step's
    # own previous_input is for that step only; a result without a plan leaves it.
    L = spec.model.num_inputs
    if spec.HasField("input_differences") and result.has_plan and len(result.inputs) >= L:
        previous = spec.input_differences.previous_input
        del previous[:]
        previous.extend(result.inputs[:L])
