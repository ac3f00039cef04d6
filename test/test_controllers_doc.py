"""docs/controllers.md: the model's code block runs as written and says what is true.

The ``python`` block under "The model" is taken from the file and run; its results are then held
to the simulator's own exact-closure forward dynamics (an oracle independent of the controller
model): the efforts it computes give back the accelerations it asked for. The ``vjm model``
table and exit codes of the same page are held to what the command prints.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from oracle.mechanism import Mechanism

from vjm_ros.app import model_cli
from vjm_ros.core.constraints import ExactClosure

DOC = Path(__file__).resolve().parents[1] / "docs" / "controllers.md"


def model_block() -> str:
    """The first ``python`` block after the heading "## The model"."""
    text = DOC.read_text()
    section = text[text.index("## The model"):]
    match = re.search(r"^```python\n(.*?)^```$", section, flags=re.S | re.M)
    assert match, f"{DOC}: no python block under '## The model'"
    return match.group(1)


@pytest.fixture(scope="module")
def ran() -> dict:
    namespace: dict = {"__name__": "__main__"}
    exec(compile(model_block(), f"{DOC}:The model", "exec"), namespace)  # as written
    return namespace


def test_the_model_block_runs_and_its_efforts_give_its_accelerations(ran):
    cm, q, qd, tau = ran["cm"], ran["q"], ran["qd"], ran["tau"]
    # the pose it asks for: the bases where it put them, the elbows bent (the guess's branch)
    names = cm.model.joint_names
    np.testing.assert_allclose(q[cm.independent], [-2.1, 3.7], atol=1e-12)
    assert q[names.index("left_elbow")] > 0.5 and q[names.index("right_elbow")] < -0.5
    np.testing.assert_allclose(cm.closure_residual(q), 0.0, atol=1e-10)
    mech = Mechanism(cm.model, ExactClosure(alpha=0.0, beta=0.0))
    # the last five_bar efforts: the pin's acceleration [0, -1] m/s^2 (1e-7: the solves'
    # round-off on efforts of a few N m, as in test_closed_model.py)
    qdd = mech.accelerations(q, qd, cm.selection @ tau)
    pin = ran["J"] @ qdd[cm.independent] + ran["b"]
    np.testing.assert_allclose(pin, [0.0, -1.0], atol=1e-7)
    joint_space = cm.inverse_dynamics(q, qd, ran["udd"])
    qdd = mech.accelerations(q, qd, cm.selection @ joint_space)
    np.testing.assert_allclose(qdd[cm.independent], ran["udd"], atol=1e-7)
    assert ran["cm"].singularity_measure(q, point="left_tip") > 0.1  # away from the start


def test_the_redundant_example_moves_as_asked_with_its_preload(ran):
    rc, q3, qd3, tau3 = ran["rc"], ran["q3"], ran["qd3"], ran["tau3"]
    mech = Mechanism(rc.model, ExactClosure(alpha=0.0, beta=0.0))
    qdd = mech.accelerations(q3, qd3, rc.selection @ tau3)
    np.testing.assert_allclose(qdd[rc.independent], [0.2, 0.1], atol=1e-7)
    without = rc.inverse_dynamics(q3, qd3, [0.2, 0.1], weights=[1, 1, 4])
    preload = tau3 - without
    assert np.max(np.abs(preload)) == pytest.approx(20.0)
    # what the page says it adds at three_chain's start
    np.testing.assert_allclose(preload, [-20.0, 9.9, -3.8], atol=0.05)


def test_the_page_lists_the_keys_and_exit_codes_of_vjm_model():
    text = DOC.read_text()
    table = text[text.index("| key | holds |"):]
    table = table[: table.index("\n\n")]
    listed = [k for row in table.splitlines()[2:] for k in re.findall(r"`(\w+)`", row.split("|")[1])]
    assert listed == list(model_cli.KEYS)
    codes = text[text.index("Exit codes of `vjm model`"):]
    codes = codes[: codes.index("\n\n")]
    assert re.findall(r"(\d) (?:done|no answer|bad input)", codes) == [
        str(k) for k in model_cli.EXIT_CODES]
