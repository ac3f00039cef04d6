"""``vjm model`` through its command line: the documented examples, keys and exit codes.

The efforts it prints are held to the simulator's exact-closure forward dynamics (the oracle of
test/oracle/mechanism.py): applied at the printed state, they give the asked acceleration.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shlex
import subprocess
import sys

import numpy as np
import pytest
from oracle.mechanism import Mechanism

from vjm_ros.app import model_cli
from vjm_ros.core.constraints import ExactClosure
from vjm_ros.scene.loader import load_scene

GUARD = 120.0  # s: a hang guard, not a speed requirement


def vjm_model(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", "model", *args],
                          capture_output=True, text=True, timeout=GUARD,
                          env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))


def vjm_model_here(*args: str) -> subprocess.CompletedProcess:
    """``vjm model ARGS`` through the command's entry point (:func:`vjm_ros.app.cli.main`, what
    the ``vjm`` script calls) in this process: its exit code, standard output and standard
    error, as :func:`vjm_model` gives them from a process of its own.

    The tests that load a model use it: a process each paid the interpreter's start and the
    loading of the compiled model (about 0.8 s) for the same code path; ``vjm model`` as a
    process of its own stays checked by :func:`vjm_model` here and by
    test_closed_model.py::test_vjm_model_prints_what_the_api_computes.
    """
    from vjm_ros.app import cli

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(["model", *args])
        except SystemExit as exc:  # argparse's refusals; the code as Python's exit makes it
            code = 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
    return subprocess.CompletedProcess(["vjm", "model", *args], code, out.getvalue(),
                                       err.getvalue())


def strict_json(text: str) -> dict:
    """The last line as JSON, refusing NaN and Infinity (not JSON)."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")

    return json.loads(text.strip().splitlines()[-1], parse_constant=refuse)


def docstring_examples() -> list[list[str]]:
    lines = [ln.strip().split("#")[0] for ln in model_cli.__doc__.splitlines()]
    return [shlex.split(ln)[2:] for ln in lines if ln.startswith("vjm model ")]


def test_udd_with_xdd_is_refused_naming_both():
    out = vjm_model("five_bar", "--state", "left_elbow=1.4", "right_elbow=-1.4", "--udd", "0",
                    "0", "--point", "left_tip", "--xdd", "0", "-1")
    assert out.returncode == 2
    assert "--xdd" in out.stderr and "--udd" in out.stderr and "not allowed" in out.stderr


@pytest.mark.parametrize("args", docstring_examples(), ids=" ".join)
def test_the_docstring_examples_run_and_their_efforts_give_what_they_ask(args):
    if "--json" not in args:
        args = [*args, "--json"]
    out = vjm_model_here(*args)
    assert out.returncode == 0, out.stderr
    got = strict_json(out.stdout)
    assert list(got) == list(model_cli.KEYS)  # the documented keys, in order
    assert got["task_point"] in got["points"]
    model = load_scene(got["scene"]).model
    q = np.array([got["q"][j] for j in model.joint_names])
    qd = np.array([got["qd"][j] for j in model.joint_names])
    tau = model.actuator_matrix() @ np.array([got["efforts"][a] for a in model.actuator_names])
    qdd = Mechanism(model, ExactClosure(alpha=0.0, beta=0.0)).accelerations(q, qd, tau)
    independent = [model.joint_names.index(j) for j in got["independent"]]
    # 1e-6: the printed numbers are exact doubles; the solves' round-off on efforts <= 1e3 N m
    if "udd" in got["asked"]:
        np.testing.assert_allclose(qdd[independent], got["asked"]["udd"], atol=1e-6)
    else:
        xdd = np.array(got["task_jacobian"]) @ qdd[independent] + np.array(got["task_bias"])
        np.testing.assert_allclose(xdd, got["asked"]["xdd"], atol=1e-6)
        assert got["task_singularity_measure"] > 0.1


@pytest.mark.slow  # compiles the controllers' model for a scene without closures (about 8 s)
def test_a_mechanism_without_closures_prints_strict_json():
    got = strict_json(vjm_model("pendulum", "--json").stdout)
    assert got["singularity_measure"] is None
    assert got["task_singularity_measure"] == pytest.approx(1.0)  # |J_t| = the arm, 1 m


@pytest.mark.parametrize("args, code, message", [
    (["five_bar", "--point", "left_tip", "--xdd", "0", "-1"], 1, "'left_tip'.*rank 0"),
    (["three_chain", "--udd", "50", "40"], 1, r"c\d_base needs .* limit of 200"),
    (["five_bar", "--preload", "5"], 2, "preload: expected redundant actuation"),
    (["three_chain", "--preload", "nan"], 2, "preload: expected a finite number"),
    (["five_bar", "--point", "pin"], 2, "point: expected a named point of five_bar"),
], ids=["singular-point", "beyond-limits", "preload-non-redundant", "preload-nan",
        "unknown-point"])
def test_exit_codes_are_the_documented_ones(args, code, message):
    out = vjm_model_here(*args)
    assert out.returncode == code, out.stderr
    assert code in model_cli.EXIT_CODES
    assert re.search(message, out.stderr), out.stderr


def test_help_lists_the_keys_and_the_exit_codes():
    text = vjm_model("--help").stdout
    for key in model_cli.KEYS:
        assert f"\n  {key} " in text, key
    for code in model_cli.EXIT_CODES:
        assert f"\n  {code}  " in text, code
