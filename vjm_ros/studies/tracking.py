"""Tracking of the computed-torque example controller against the simulator, as users run them.

Two processes on this machine's ROS graph: ``vjm_sim_node`` (exact closure, 1 kHz, lockstep or
realtime, recording its MCAP log) and ``vjm_ct_controller``. The log, read back with rosbags,
gives the tracked point's path (from the joint states and the scene in the log) against the
desired one: RMS and largest error after the approach, and the efforts. Both processes run on
the environment's ``ROS_DOMAIN_ID`` (one of the study's own when it is not set). Re-run with::

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python -m vjm_ros.studies.tracking [--figure FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CASES = {
    "five_bar_circle": {
        "scene": "five_bar", "path": "circle", "size": 0.05, "period": 2.0,
        "initial": {"left_elbow": 1.4, "right_elbow": -1.4}, "preload": 0.0,
    },
    "three_chain_figure8": {
        "scene": "three_chain", "path": "figure8", "size": 0.2, "period": 4.0,
        "initial": {}, "preload": 0.0,
    },
    "three_chain_figure8_preload": {
        "scene": "three_chain", "path": "figure8", "size": 0.2, "period": 4.0,
        "initial": {}, "preload": 20.0,
    },
    "five_bar_friction_circle": {
        "scene": "five_bar_friction", "path": "circle", "size": 0.05, "period": 2.0,
        "initial": {}, "preload": 0.0, "compensate_plant": False,
    },
    "five_bar_friction_circle_compensated": {
        "scene": "five_bar_friction", "path": "circle", "size": 0.05, "period": 2.0,
        "initial": {}, "preload": 0.0, "compensate_plant": True,
    },
}
"""The example runs: the five-bar's pin on a circle (started away from the thesis's singular
pose), the redundant three-chain's pin on a figure-eight without and with a 20 N m preload, and
the five-bar with joint friction (``five_bar_friction``) on the same circle, the controller's
model without and with the plant's friction and damping (``compensate_plant``)."""


@dataclass
class Tracking:
    """One run's outcome."""

    case: str
    mode: str
    rms_mm: float
    max_mm: float
    states: int
    t: np.ndarray = field(repr=False)
    actual: np.ndarray = field(repr=False)
    desired: np.ndarray = field(repr=False)
    efforts: np.ndarray = field(repr=False)
    effort_names: list = field(default_factory=list)


MAX_DOMAIN = 232
"""The largest ``ROS_DOMAIN_ID`` ROS 2 accepts."""


def ros_domain() -> int:
    """The ROS domain of the study's simulator and controller.

    The environment's ``ROS_DOMAIN_ID`` when it is set, so that a user can watch the run or keep
    it apart from other graphs; otherwise one of the study's own, ``1 + pid % 101`` (within the
    0-101 that every platform's DDS ports allow), named on stderr.

    Raises
    ------
    ValueError
        ``ROS_DOMAIN_ID`` is set to something other than a whole number from 0 to 232.
    """
    value = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not value:
        domain = 1 + os.getpid() % 101
        print(f"ROS_DOMAIN_ID is not set: the study runs on domain {domain}", file=sys.stderr)
        return domain
    if not (value.isascii() and value.isdigit()) or int(value) > MAX_DOMAIN:
        raise ValueError(
            f"ROS_DOMAIN_ID: expected a whole number from 0 to {MAX_DOMAIN}, found {value!r}")
    return int(value)


def _env(domain: int) -> dict:
    return dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain))


def run_case(case: str, mode: str = "lockstep", duration: float = 4.0, settle: float = 1.5,
             domain: int | None = None) -> Tracking:
    """Run one case (``mode`` ``lockstep`` or ``realtime``) and measure its tracking.

    ``domain``: the ROS domain of its two processes (default: :func:`ros_domain`).
    """
    spec = CASES[case]
    domain = domain if domain is not None else ros_domain()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "run.mcap"
        sim_cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args",
                   "-p", f"scene:={spec['scene']}", "-p", "closure:=exact",
                   "-p", "wait_for_command:=true", "-p", f"duration:={duration}",
                   "-p", "command_timeout:=0.0", "-p", f"mcap:={log}"]
        if mode == "lockstep":
            sim_cmd += ["-p", "lockstep:=true", "-p", "lockstep_timeout:=30.0",
                        "-p", "realtime:=false"]
        for joint, value in spec["initial"].items():
            sim_cmd += ["-p", f"initial_positions.{joint}:={value}"]
        ctl_cmd = [sys.executable, "-m", "vjm_ros.ros.computed_torque", "--ros-args",
                   "-p", f"path:={spec['path']}", "-p", f"size:={spec['size']}",
                   "-p", f"period:={spec['period']}", "-p", f"preload:={spec['preload']}",
                   "-p", f"compensate_plant:={str(spec.get('compensate_plant', False)).lower()}"]
        sim = subprocess.Popen(sim_cmd, env=_env(domain), stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
        ctl = subprocess.Popen(ctl_cmd, env=_env(domain), stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
        try:
            out, _ = sim.communicate(timeout=300 + 10 * duration)  # a hang guard
        finally:
            for proc in (sim, ctl):
                if proc.poll() is None:
                    proc.send_signal(signal.SIGINT)
                    try:
                        proc.communicate(timeout=30)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.communicate()
        if sim.returncode != 0:
            raise RuntimeError(f"the simulator failed ({sim.returncode}):\n{out}")
        return measure(log, case, mode, settle)


def measure(log: Path, case: str, mode: str, settle: float) -> Tracking:
    """Tracking error of a run from its MCAP log, read with rosbags."""
    from rosbags.highlevel import AnyReader

    from vjm_ros.control import ClosedChainModel
    from vjm_ros.control.paths import PATHS
    from vjm_ros.logs.replay import read_info

    spec = CASES[case]
    cm = ClosedChainModel.from_yaml(read_info(log).scene_text, closure_tolerance=1.0)
    names, point = cm.model.joint_names, cm.model.points[0].name
    acts = cm.model.actuator_names
    rows = []
    with AnyReader([log]) as reader:
        conns = [c for c in reader.connections if c.topic.endswith("joint_states")]
        for conn, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            order = list(m.name)
            rows.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec,
                         [m.position[order.index(n)] for n in names],
                         [m.effort[order.index(a)] for a in acts]))
    t = np.array([r[0] for r in rows])
    t, first = np.unique(t, return_index=True)  # the held start state comes more than once
    q = np.array([rows[i][1] for i in first])
    efforts = np.array([rows[i][2] for i in first])
    actual = np.array([cm.forward_kinematics(qi, point) for qi in q])
    path = PATHS[spec["path"]](tuple(actual[0]), spec["size"], spec["period"], 1.0)
    desired = np.array([path.at(ti - t[0])[0] for ti in t])
    err = np.linalg.norm(actual - desired, axis=1)
    late = t - t[0] >= settle
    return Tracking(case, mode, float(np.sqrt(np.mean(err[late] ** 2)) * 1e3),
                    float(err[late].max() * 1e3), len(t), t - t[0], actual, desired, efforts,
                    acts)


def figure(results: list[Tracking], path: str | Path) -> Path:
    """Desired and actual paths, and the efforts, of each case (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(results), figsize=(4.2 * len(results), 7.0), dpi=110,
                             squeeze=False)
    for col, r in enumerate(results):
        ax = axes[0, col]
        ax.plot(r.desired[:, 0], r.desired[:, 1], "k--", lw=1.0, label="desired")
        ax.plot(r.actual[:, 0], r.actual[:, 1], "C1-", lw=1.0, alpha=0.8, label="actual")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{r.case} ({r.mode})\nRMS {r.rms_mm:.4f} mm, max {r.max_mm:.4f} mm",
                     fontsize=9)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(fontsize=7)
        ax = axes[1, col]
        for k, name in enumerate(r.effort_names):
            ax.plot(r.t, r.efforts[:, k], lw=0.9, label=name)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("effort (N m)")
        ax.legend(fontsize=7)
        ax.grid(True, lw=0.3, alpha=0.5)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module documentation."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    p = argparse.ArgumentParser(prog="python -m vjm_ros.studies.tracking",
                                description=__doc__.split("\n")[0])
    p.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    p.add_argument("--modes", nargs="*", default=["lockstep", "realtime"],
                   choices=["lockstep", "realtime"])
    p.add_argument("--duration", type=float, default=4.0, help="simulated s per run (4)")
    p.add_argument("--figure", type=Path, help="write the lockstep runs' figure here (PNG)")
    args = p.parse_args(argv)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    try:
        domain = ros_domain()
    except ValueError as exc:
        p.error(str(exc))  # exit code 2
    results = []
    for mode in args.modes:
        for case in args.cases:
            t0 = time.monotonic()
            r = run_case(case, mode, args.duration, domain=domain)
            results.append(r)
            print(f"{case:>28} {mode:>8}: RMS {r.rms_mm:.5f} mm, max {r.max_mm:.5f} mm, "
                  f"{r.states} states ({time.monotonic() - t0:.0f} s)", flush=True)
    if args.figure:
        figure([r for r in results if r.mode == "lockstep"], args.figure)
    print(json.dumps([{"case": r.case, "mode": r.mode, "rms_mm": r.rms_mm, "max_mm": r.max_mm}
                      for r in results]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
