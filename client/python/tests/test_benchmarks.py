"""Every shared benchmark instance, read by nupmpc.load_instance and solved by SolveOnce,
gives the objective of the C++ CLI (`nupmpc solve FILE --format json`, which reads the
file with client/problem_file.cc) on the same server: the two readers agree."""

import json
import os
import subprocess

import pytest

import nupmpc
from conftest import BENCHMARKS, CLI_BINARY

INSTANCES = sorted(p for p in BENCHMARKS.glob("*.json") if p.name != "reference.json")


def test_there_are_instances_to_compare():
    assert len(INSTANCES) >= 10, INSTANCES  # benchmarks/ holds 10


def test_every_instance_through_solve_once_matches_the_cli(server):
    if not os.access(CLI_BINARY, os.X_OK):
        pytest.fail(f"no CLI binary at {CLI_BINARY} (build nupmpc or set NUPMPC_CLI_BINARY)")
    # The CLI runs beside the Python solves (both mostly parse JSON; the server has 2 workers).
    cli = {path.name: subprocess.Popen([CLI_BINARY, "--server", server.target, "--format", "json", "solve", str(path)],
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
           for path in INSTANCES}
    ours = {}
    with nupmpc.connect(server.target) as client:
        for path in INSTANCES:
            instance = nupmpc.load_instance(path)
            assert instance.name == path.stem
            ours[path.name] = client.solve_once(instance.spec)
    for name, process in cli.items():
        out, err = process.communicate(timeout=120)
        assert process.returncode == 0, (name, err)
        theirs = json.loads(out)
        plan = ours[name]
        assert plan.status.lower() == theirs["status"], name
        assert abs(plan.objective - theirs["objective"]) <= 1e-12 * abs(theirs["objective"]), \
            (name, plan.objective, theirs["objective"])
        assert list(plan.u0) == pytest.approx(theirs["u0"], rel=1e-5, abs=1e-6), name  # printed to 6 digits


def test_closed_loop_states_and_dimensions_are_read(masses):
    assert masses.closed_loop_states.shape == (100, 12)
    problem = masses.problem
    assert (problem.M, problem.L, problem.K, problem.N) == (12, 3, 12, 30)
    lower, upper = problem.bounds("input")
    assert lower.shape == (30, 3) and (lower == -0.5).all() and (upper == 0.5).all()


def test_a_malformed_instance_names_the_file_and_the_field(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"dims": {"M": 1, "L": 1, "K": 0, "N": 2}, "A": [[1]], "B": [[1]],
                               "x1": [0], "R": [[1, 2], [3, 4]]}))
    with pytest.raises(ValueError) as caught:
        nupmpc.load_instance(bad)
    assert str(bad) in str(caught.value) and "R: expected 1x1" in str(caught.value)
    assert caught.value.field == "R"
