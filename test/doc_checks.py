"""The ``text check:NAME`` blocks of the docs: what produces each for real, and the comparison.

Each check takes the block and a fresh directory, runs the program the block shows the output
of (or, for a formula, the code that computes it), and fails with both texts when they differ.
Numbers are masked only where they vary between runs or machines.
"""

from __future__ import annotations

import io
import os
import re
import shlex
import signal
from collections.abc import Callable
from contextlib import redirect_stdout
from pathlib import Path

import pytest
from doc_blocks import (
    DOMAIN,
    HANG_GUARD,
    VENV_BIN,
    Block,
    command_env,
    finish,
    flat,
    masked,
    start,
    stop,
    synopsis_options,
    without_stamp,
)


def help_text(*argv: str) -> str:
    """What ``vjm ARGV --help`` prints (the entry point's own ``main``, in this process)."""
    from vjm_ros.app import cli

    buf = io.StringIO()
    with redirect_stdout(buf), pytest.raises(SystemExit) as exit_:
        cli.main([*argv, "--help"])
    assert exit_.value.code == 0
    return buf.getvalue()


def check_vjm_usage(block: Block, tmp_path: Path) -> None:
    """Each ``vjm CMD ...`` line against ``vjm CMD --help``: the subcommands are all there, and
    every option the doc shows exists, is optional or required as shown, and takes a value or
    not as shown (positionals and omitted options are not compared)."""
    entries: list[list[str]] = []
    for line in block.text.splitlines():
        code = line.split("  #")[0].rstrip()
        if code.startswith("vjm "):
            entries.append([code])
        elif code.strip():
            entries[-1].append(code)
    shown = {" ".join(e).split()[1]: " ".join(e) for e in entries}
    listed = re.search(r"\{([\w,]+)\}", help_text()).group(1).split(",")
    assert sorted(shown) == sorted(listed), f"the doc lists {sorted(shown)}, vjm has {listed}"
    wrong = []
    for command, synopsis in shown.items():
        usage = help_text(command).split("\n\n")[0]
        real = synopsis_options(usage)
        for option, (optional, value) in synopsis_options(synopsis).items():
            if option not in real:
                wrong.append(f"vjm {command}: {option} is not an option ({usage})")
            elif real[option] != (optional, value):
                wrong.append(f"vjm {command} {option}: shown (optional, takes a value) = "
                             f"{(optional, value)}, vjm says {real[option]}")
    assert not wrong, "\n".join(wrong)


def check_scene_error(block: Block, tmp_path: Path) -> None:
    """The form of a scene error, from a real one: ``FILE``, ``KEY``, ``WHAT`` and ``VALUE`` are
    the error's ``source``, ``key``, ``expected`` and ``found``."""
    from vjm_ros.core.errors import SceneError
    from vjm_ros.scene.loader import builtin_scene_text, load_scene

    path = tmp_path / "heavy.yaml"
    path.write_text(builtin_scene_text("four_bar").replace("mass: 1.0", "mass: heavy", 1))
    with pytest.raises(SceneError) as info:
        load_scene(str(path))
    pattern = re.escape(flat(block.text))
    for placeholder in ("FILE", "KEY", "WHAT", "VALUE"):
        pattern = pattern.replace(placeholder, "(.+)", 1)
    match = re.fullmatch(pattern, str(info.value))
    assert match, f"{str(info.value)!r} does not read {flat(block.text)!r}"
    exc = info.value
    assert match.groups() == (exc.source, exc.key, exc.expected, repr(exc.found)), match.groups()


def vjm_output(cwd: Path, *argv: str, code: int) -> str:
    proc = start(shlex.join([str(VENV_BIN / "vjm"), *argv]), cwd, command_env("tmp"))
    out = finish(proc, HANG_GUARD, f"vjm {' '.join(argv)}")
    assert proc.returncode == code, out
    return out


def check_stiffness_error(block: Block, tmp_path: Path) -> None:
    """The message of ``vjm run four_bar --rate 100`` (the thesis gains at h = 0.01 s), word for
    word."""
    out = vjm_output(tmp_path, "run", "four_bar", "--rate", "100",
                     code=2)
    assert f"vjm: error: {flat(block.text)}" in flat(out), out


FIVE_BAR_ON_A_LINE = """\
name: five_bar_on_a_line
units: {angle: degrees}
chains:
  - name: left
    links:
      - {name: left_proximal, length: 0.25, mass: 1.0, com: [0.125, 0.0],
         joint: {name: left_base, type: revolute, angle: 0.0}}
      - {name: left_distal, length: 0.75, mass: 1.0, com: [0.375, 0.0],
         joint: {name: left_elbow, type: revolute, angle: 0.0}}
  - name: right
    length: 2.0
    links:
      - {name: right_proximal, length: 0.25, mass: 1.0, com: [0.125, 0.0],
         joint: {name: right_base, type: revolute, angle: 180.0}}
      - {name: right_distal, length: 0.75, mass: 1.0, com: [0.375, 0.0],
         joint: {name: right_elbow, type: revolute, angle: 180.0}}
closures:
  - {name: pin, type: hinge, point: {link: left_distal, at: tip},
     target: {link: right_distal, at: tip}}
actuators: [{joint: left_base, limit: 50.0}, {joint: right_base, limit: 50.0}]
"""
"""The five-bar with both legs stretched along one line (bases 2 m apart): the closure Jacobian
has rank 1 there, and gravity asks exact closure for unbounded forces."""


def check_divergence_error(block: Block, tmp_path: Path) -> None:
    """The message of a real divergence (exact closure from a singular pose), numbers masked
    (the singular values at the start are round-off)."""
    cwd = tmp_path
    (cwd / "line.yaml").write_text(FIVE_BAR_ON_A_LINE)
    out = vjm_output(cwd, "run", "line.yaml", "--closure", "exact", code=3)
    assert f"vjm: {masked(block.text)}" in masked(out), out


COMMANDER = """\
import sys, time
import rclpy
from std_msgs.msg import Float64MultiArray
rclpy.init()
node = rclpy.create_node("doc_commander")
pub = node.create_publisher(Float64MultiArray, "/vjm_sim_node/effort_commands", 10)
end = time.monotonic() + 60  # a hang guard
while pub.get_subscription_count() == 0:
    if time.monotonic() > end:
        sys.exit("no subscriber")
    time.sleep(0.01)
pub.publish(Float64MultiArray(data=[1.0, 2.0, 3.0]))  # refused: five_bar has two actuators
time.sleep(0.2)
pub.publish(Float64MultiArray(data=[0.0, 0.0]))  # starts the run; then it times out
time.sleep(0.2)
node.destroy_node()
rclpy.shutdown()
"""


_NODE_WARNINGS: list[str] = []


def node_warnings(tmp_path: Path) -> list[str]:
    """What ``vjm_sim_node`` prints on five_bar given a command of three values, then one valid
    command and nothing after it (``command_timeout`` 0.5 s, within the 0.7 s run); lines without
    their stamps. Run once per test process (both warnings come from the one run)."""
    if _NODE_WARNINGS:
        return _NODE_WARNINGS
    (tmp_path / "commander.py").write_text(COMMANDER)
    env = command_env("tmp")
    node = start("exec vjm_sim_node --ros-args -p scene:=five_bar -p wait_for_command:=true "
                 "-p duration:=0.7", tmp_path, env)
    commander = start(f"exec {shlex.quote(str(VENV_BIN / 'python'))} commander.py", tmp_path, env)
    try:
        out = finish(node, HANG_GUARD, "vjm_sim_node")
        finish(commander, HANG_GUARD, "the commander")
    finally:
        stop(node, signal.SIGKILL)
        stop(commander, signal.SIGKILL)
    assert node.returncode == 0 and commander.returncode == 0, out
    _NODE_WARNINGS.extend(without_stamp(line) for line in out.splitlines())
    return _NODE_WARNINGS


def check_refused_command(block: Block, tmp_path: Path) -> None:
    lines = node_warnings(tmp_path)
    assert flat(block.text) in lines, "\n".join(lines)


def check_command_timeout(block: Block, tmp_path: Path) -> None:
    lines = node_warnings(tmp_path)
    assert masked(block.text) in [masked(line) for line in lines], "\n".join(lines)


def check_computed_torque_law(block: Block, tmp_path: Path) -> None:
    """The law and gains shown are what ``vjm_ct_controller`` computes: its efforts at a moving
    five_bar state equal the doc's two lines evaluated as written (``kp (e)`` read as a product,
    the gains from the comment), to round-off."""
    import numpy as np
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from vjm_ros.control.paths import PATHS
    from vjm_ros.ros.computed_torque import ComputedTorqueNode

    gains = dict(re.findall(r"\b(k[pd]) = ([\d.]+)", block.text))
    assert set(gains) == {"kp", "kd"}, block.text
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(DOMAIN),
               signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = ComputedTorqueNode(context=context, parameter_overrides=[
            Parameter("scene", value="five_bar"), Parameter("description_timeout", value=0.2),
            Parameter("preload", value=0.0),
            Parameter("simulator", value=f"no_simulator_{os.getpid()}")])
        try:
            cm, point = node.cm, node.point
            q = cm.assemble([-0.6, 2.2], guess=cm.model.initial_state()[0])
            qd = cm.dependent_velocities(q, [0.5, -0.2])
            start_point = tuple(cm.forward_kinematics(q, point) + [0.01, -0.02])
            node.path = PATHS["circle"](start_point, 0.05, 2.0, 1.0)
            t = 1.3
            tau = node.efforts(q, qd, t)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    x_d, xd_d, xdd_d = node.path.at(t)
    names = {"xdd_d": xdd_d, "xd_d": xd_d, "x_d": x_d, "x": cm.forward_kinematics(q, point),
             "xd": cm.task_jacobian(q, point) @ qd[cm.independent], "cm": cm, "q": q,
             "qd": qd, "P": point, **{k: float(v) for k, v in gains.items()}}
    law = re.sub(r"\b(k[pd]) \(", r"\1 * (", block.text).replace("preload=...", "preload=0.0")
    exec(compile(law, block.id, "exec"), {}, names)
    # round-off of the same operations in another order: 1e-9 of efforts of order 1-10 N m
    assert np.allclose(names["tau"], tau, rtol=0, atol=1e-9), (names["tau"], tau)
    assert not np.allclose(tau, 0.0)


CHECKS: dict[str, Callable[[Block, Path], None]] = {
    "vjm-usage": check_vjm_usage,
    "scene-error": check_scene_error,
    "stiffness-error": check_stiffness_error,
    "divergence-error": check_divergence_error,
    "refused-command-warning": check_refused_command,
    "command-timeout-warning": check_command_timeout,
    "computed-torque-law": check_computed_torque_law,
}
"""``text check:NAME`` blocks: what produces each for real and compares it."""

