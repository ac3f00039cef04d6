"""Command line interface ``vjm`` (works without ROS).

Subcommands: ``scenes``, ``run``, ``model``, ``bench``, ``sweep``, ``tune``, ``replay``,
``recover``, ``export``. See
docs/design.md section 5.

Exit codes of ``vjm run``: 0 success; 2 bad input (scene file, setting, stiffness refused before
running, a log path that cannot be written or a nearly full disk); 3 the simulation diverged (what
was recorded up to then is written); 4 a log could not be written during the run (the run went on
without it; see :mod:`vjm_ros.logs.storage`); 130 interrupted by SIGINT and 143 by SIGTERM
(outputs recorded so far are written and log files finalized).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from vjm_ros.core.errors import ConfigurationError, DivergenceError, SceneError, VjmError
from vjm_ros.logs.signals import StopSignals

DEFAULT_SCENE = "four_bar"
EXIT_BAD_INPUT = 2
EXIT_DIVERGED = 3
EXIT_LOG_FAILED = 4


class Progress:
    """A one-line progress bar on stderr, shown only on a terminal for runs longer than ~2 s."""

    def __init__(self, total: float, enabled: bool):
        self.total = total
        self.enabled = enabled
        self.start = time.perf_counter()
        self.last = 0.0
        self.shown = False

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < 0.2 or now - self.start < 2.0:
            return
        self.last = now
        frac = min(done / self.total, 1.0) if self.total > 0 else 1.0
        width = 30
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        eta = (now - self.start) * (1 - frac) / frac if frac > 0 else float("nan")
        sys.stderr.write(f"\r[{bar}] {100 * frac:5.1f}%  sim {done:7.2f} s  eta {eta:5.0f} s")
        sys.stderr.flush()
        self.shown = True

    def close(self) -> None:
        if self.shown:
            sys.stderr.write("\n")
            sys.stderr.flush()


def _parser() -> argparse.ArgumentParser:
    from vjm_ros.core.integrators import INTEGRATORS

    p = argparse.ArgumentParser(
        prog="vjm", description="Planar closed-chain mechanisms by the virtual joint method."
    )
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("scenes", help="list the built-in scenes")

    r = sub.add_parser("run", help="simulate a scene and write its trajectory and measures")
    r.add_argument(
        "scene",
        nargs="?",
        default=DEFAULT_SCENE,
        help=f"built-in scene name or YAML path (default: {DEFAULT_SCENE})",
    )
    r.add_argument("--duration", type=float, help="simulated seconds (scene default, else 10)")
    r.add_argument(
        "--rate", type=float, help="control ticks per second, Hz (scene default, else 1000)"
    )
    r.add_argument("--substeps", type=int, help="fixed steps per tick (scene default, else 1)")
    r.add_argument("--integrator", choices=list(INTEGRATORS), help="time-stepping method")
    r.add_argument("--closure", choices=["penalty", "exact"], help="closure method")
    r.add_argument("--kp", type=float, help="penalty stiffness, N/m")
    r.add_argument("--kv", type=float, help="penalty damping, N s/m")
    r.add_argument("--omega-n", type=float, help="penalty natural frequency per row, rad/s")
    r.add_argument("--zeta", type=float, help="penalty damping ratio per row")
    r.add_argument("--alpha", type=float, help="Baumgarte velocity gain (exact), 1/s")
    r.add_argument("--beta", type=float, help="Baumgarte position gain (exact), 1/s")
    r.add_argument("--projection", action="store_true", help="exact: project q, qd each tick")
    r.add_argument("--rtol", type=float, default=1e-9, help="adaptive integrators' rtol")
    r.add_argument("--atol", type=float, default=1e-12, help="adaptive integrators' atol")
    r.add_argument(
        "--effort",
        type=float,
        nargs="+",
        metavar="E",
        help="constant actuator efforts in the scene's actuator order, N m or N",
    )
    r.add_argument(
        "--kernel",
        metavar="{auto,numba}",
        default="auto",
        help="physics kernels: 'auto' (machine code with numba, plain Python without) or "
        "'numba' (an error without numba) (default: auto)",
    )
    r.add_argument(
        "--no-stiffness-check",
        action="store_true",
        help="run even if the penalty gains exceed the integrator's stability bound",
    )
    r.add_argument("--out", type=Path, help="directory for trajectory.csv and summary.json")
    r.add_argument("--mcap", type=Path, help="write a ROS 2 MCAP log")
    r.add_argument("--bag", type=Path, metavar="DIR",
                   help="write a rosbag2 directory (metadata.yaml and DIR_0.mcap)")
    r.add_argument("--rrd", help="write a rerun recording (.rrd path, 'spawn' or 'connect')")
    r.add_argument(
        "--plots", action="store_true", help="write the thesis figure set (PNG) to --out"
    )
    r.add_argument("--json", action="store_true", help="print the summary as JSON on the last line")

    for name, text in (("bench", "speed/accuracy study"),
                       ("sweep", "a grid of runs from a spec, on Dask"),
                       ("tune", "penalty gains for an integrator and step")):
        sub.add_parser(name, help=text, add_help=False).add_argument(
            "rest", nargs=argparse.REMAINDER)
    from vjm_ros.app import export_cli, import_cli, model_cli

    model_cli.add_parser(sub)
    import_cli.add_parser(sub)
    export_cli.add_parser(sub)
    rp = sub.add_parser("replay", help="rerun recording from an MCAP log")
    rp.add_argument("mcap", type=Path)
    rp.add_argument("-o", "--output", type=Path, help="output .rrd (default: next to the log)")
    rc = sub.add_parser("recover", help="readable copy of a truncated MCAP log")
    rc.add_argument("mcap", type=Path)
    rc.add_argument("-o", "--output", type=Path, required=True)
    return p


EXIT_CLOSED_PIPE = 141
"""Exit code when the reader of standard output went away (``vjm scenes | head``): the shell's
code for a process ended by SIGPIPE."""


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``vjm`` command."""
    try:
        return _main(argv)
    except BrokenPipeError:
        # The reader closed the pipe: stop quietly, as a process killed by SIGPIPE would, and keep
        # Python from failing again when it flushes stdout at exit.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_CLOSED_PIPE


def _main(argv: list[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["bench"]:
        from vjm_ros.studies.bench import main as bench_main

        return bench_main(argv[1:])
    if argv[:1] in (["sweep"], ["tune"]):
        from vjm_ros.studies.sweep import cli as sweep_cli

        return sweep_cli.main(argv[0], argv[1:])
    args = _parser().parse_args(argv)
    try:
        if args.command == "scenes":
            return _cmd_scenes()
        if args.command == "run":
            return _cmd_run(args)
        if args.command in ("model", "import", "export"):
            return importlib.import_module(f"vjm_ros.app.{args.command}_cli").run(args)
        if args.command == "replay":
            from vjm_ros.logs.replay import replay

            out = args.output or args.mcap.with_suffix(".rrd")
            info = _log_io(lambda: replay(args.mcap, out), args.mcap)
            _warn_damage(info.get("damage", []))
            print(json.dumps({"rrd": str(out), **(info or {})}))
            return 0
        if args.command == "recover":
            from vjm_ros.logs.replay import recover

            damage: list[str] = []
            count = _log_io(lambda: recover(args.mcap, args.output, damage), args.mcap)
            _warn_damage(damage)
            print(f"recovered {count} messages into {args.output}")
            return 0
    except (SceneError, ConfigurationError) as exc:
        print(f"vjm: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except VjmError as exc:
        print(f"vjm: error: {exc}", file=sys.stderr)
        return 1
    return 0


def _warn_damage(lines: list[str]) -> None:
    """Say on stderr where a truncated or damaged log stopped being readable, and why."""
    for line in lines:
        print(f"vjm: warning: {line}", file=sys.stderr)


def _log_io(action, path: Path):
    """Run a log read/write; turn I/O and format failures into a ConfigurationError."""
    if not path.is_file():
        raise ConfigurationError(f"{path}: expected an MCAP file, found no such file")
    try:
        return action()
    except VjmError:
        raise
    except (OSError, ValueError, RuntimeError) as exc:
        raise ConfigurationError(f"{path}: {exc}") from None


def _cmd_scenes() -> int:
    from vjm_ros.scene.loader import builtin_scenes, load_scene

    for name in builtin_scenes():
        sc = load_scene(name)
        desc = " ".join(str(sc.model.extras.get("description", "")).split())
        print(f"{name:16s} {sc.model.n:2d} joints, {len(sc.model.closures)} closures  {desc[:90]}")
    return 0


def _settings(args, scene):
    from vjm_ros.sim.settings import resolve_settings

    return resolve_settings(
        scene.defaults,
        scene.gains,
        **{key: getattr(args, key) for key in ("integrator", "closure", "rate", "substeps", "kp",
                                               "kv", "omega_n", "zeta", "alpha", "beta", "rtol",
                                               "atol", "kernel")},
        projection=True if args.projection else None,
        check_stiffness=not args.no_stiffness_check,
        flag=lambda key: "--" + key.replace("_", "-"),
    )


def _tell_compiling(sim) -> bool:
    """Say so on stderr when the kernels run as plain Python while they compile (a first run on
    a machine, :mod:`vjm_ros.jit.tiers`); whether it was said."""
    if not sim.mechanism.compiling:
        return False
    print("vjm: the compiled kernels are not in numba's cache yet (a first run on this "
          "machine): the run goes on as plain Python while a background process compiles "
          "them, and compiled once they are there", file=sys.stderr)
    return True


def _cmd_run(args) -> int:
    # A signal while the scene and the compiled code load is a request to stop, as later in the
    # run: with Python's default handler, the KeyboardInterrupt could be raised inside numba's
    # cache loading (a ctypes callback), which swallowed it, and the run went on.
    with StopSignals() as startup:
        return _run(args, startup)


def _run(args, startup: StopSignals) -> int:
    """``vjm run``; ``startup`` holds a signal that came before the run's own handling."""
    from vjm_ros.app.run_outputs import preload_libraries

    wanted = [key for key, on in (("csv", args.out), ("mcap", args.mcap or args.bag),
                                  ("rrd", args.rrd)) if on]
    preloading = preload_libraries(wanted) if wanted else None
    from vjm_ros.core.mechanism import PLAIN_PART_TICKS
    from vjm_ros.jit import tiers
    from vjm_ros.scene.loader import load_scene
    from vjm_ros.sim.samples import FIRST_BLOCK_TICKS, RUN_BLOCK_TICKS
    from vjm_ros.sim.simulator import Simulator
    from vjm_ros.sim.trajectory import Trajectory, prepare_csv_writer

    scene = load_scene(args.scene)
    settings = _settings(args, scene)
    duration = args.duration if args.duration is not None else scene.defaults.get("duration", 10.0)
    if not (np.isfinite(duration) and duration > 0):
        raise ConfigurationError(
            f"--duration: expected a positive number of seconds, found {duration}"
        )
    if args.plots and args.out is None:
        raise ConfigurationError("--plots needs --out DIR")
    sim = Simulator(scene.model, settings, scene.gains, scene.plant)
    if args.effort is not None:
        sim.set_efforts(np.array(args.effort))
    elif scene.model.actuators:
        sim.set_efforts(np.array([a.effort for a in scene.model.actuators]))
    if args.out is not None:
        _prepare_dir(args.out)

    traj = Trajectory(scene.model, capacity=int(duration * settings.rate) + 2,
                      measured=sim.sensors is not None)
    ticks = int(round(duration * settings.rate))
    progress = Progress(duration, sys.stderr.isatty() and sys.stdout.isatty())
    # Installed before any log is opened: from here on a signal ends the run between two blocks
    # and every log is finalized.
    code, error = 0, None
    outputs = None
    told = False
    if args.out is not None:  # loading the CSV's compiled writer is start-up too
        prepare_csv_writer(ticks + 1)
    if preloading is not None:  # library imports are start-up, like loading compiled code
        preloading.join()
    wall0, loading0 = time.perf_counter(), tiers.loading_seconds()  # set again at the first tick
    cpu0 = time.process_time()
    with StopSignals() as stop:
        stop.code = startup.code  # a signal during start-up: no tick, every log finalized
        try:
            openers = _log_openers(args, scene, sim, duration, ticks + 1)
            first = sim.sample()
            traj.append(first)
            # Blocks of ticks, each one compiled call where the integrator allows it; signals and
            # progress are taken between blocks. The trajectory and its CSV, and the logs, take
            # the blocks in threads of their own while the next blocks are computed.
            from vjm_ros.app.run_outputs import RunOutputs

            outputs = RunOutputs(traj, first, openers, _report_log_failure,
                                 None if args.out is None else args.out / "trajectory.csv",
                                 RUN_BLOCK_TICKS)
            # Start-up, before the clock: the logs open in their threads (their headers and the
            # first sample written) while the compiled pipeline loads here (a run of no more
            # ticks than the pipeline's first plain-Python call leaves numba unloaded).
            if ticks > PLAIN_PART_TICKS:
                sim.blocks_compiled()
            outputs.wait_opened()
            wall0, loading0 = time.perf_counter(), tiers.loading_seconds()
            cpu0 = time.process_time()
            block_ticks = min(FIRST_BLOCK_TICKS, RUN_BLOCK_TICKS)  # growing to it
            while sim.ticks < ticks and not stop.requested:
                block = outputs.take()
                block.rows = 0
                try:
                    sim.advance_block(block, min(block_ticks, ticks - sim.ticks))
                    block_ticks = min(RUN_BLOCK_TICKS, block_ticks * 3 // 2)
                finally:  # the ticks before a divergence are kept
                    outputs.put(block)
                progress.update(sim.t)
                told = told or _tell_compiling(sim)
        except DivergenceError as exc:
            code, error = EXIT_DIVERGED, str(exc)
        finally:
            last_tick = time.perf_counter()
            progress.close()
            try:
                if outputs is not None:
                    outputs.close()  # every block written, the CSV closed, the logs finalized
            finally:
                # the loading of compiled code (after the first ticks as plain Python) is left
                # out, as when it came before the clock started
                loading = tiers.loading_seconds() - loading0
                end = time.perf_counter()
                wall = end - wall0 - loading
                waited = min(max(end - last_tick, 0.0), max(wall, 0.0))
                cpu = max(time.process_time() - cpu0 - loading, 0.0)
                if outputs is not None:
                    outputs.logs.close()
                    mcap = outputs.recorders.get("--bag")
                    if mcap is not None and mcap in outputs.logs.active:
                        _write_bag_metadata(args.bag, mcap, outputs.logs)
    logs = outputs.logs if outputs is not None else None
    if stop.code and not code:
        code, error = stop.code, f"interrupted by signal {stop.code - 128}"
    if logs is not None and logs.failed and not code:
        code = EXIT_LOG_FAILED
        error = "; ".join(f"log {where} could not be written ({why})" for where, why in logs.failed)
    summary = traj.summary(_run_info(sim, wall, cpu, waited))
    if error:
        summary["error"] = error
        summary["finite"] = bool(summary["finite"] and code != EXIT_DIVERGED)
    if args.out is not None:
        (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        if args.plots and len(traj) > 1:
            from vjm_ros.app.plotting import write_figures

            write_figures(traj, args.out)
    if error:
        print(f"vjm: {error}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    else:
        _print_summary(summary)
    return code


def _prepare_dir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".vjm_write_test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ConfigurationError(
            f"--out {path}: expected a writable directory ({exc.strerror or exc})"
        ) from None


def _prepare_bag(bag: Path) -> None:
    if bag.exists() and (not bag.is_dir() or any(bag.iterdir())):
        raise ConfigurationError(f"--bag {bag}: expected a new or empty directory, found one in use")
    try:
        bag.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigurationError(f"--bag {bag}: cannot create it ({exc.strerror or exc})") from None


def _write_bag_metadata(bag: Path, recorder, logs) -> None:
    """``metadata.yaml`` of the bag; a failure counts as a failed log (exit 4)."""
    from vjm_ros.logs.rosbag2 import write_bag_metadata

    try:
        write_bag_metadata(bag, recorder.bag_metadata())
    except OSError as exc:
        where, why = str(bag / "metadata.yaml"), exc.strerror or str(exc)
        logs.failed.append((where, why))
        _report_log_failure(where, why)


def _log_openers(args, scene, sim, duration: float, samples: int) -> list:
    """The storage checks of the logs asked for, and a function per log that opens it
    (``samples``: how many the run will write)."""
    from vjm_ros.app.run_outputs import MCAP_CHUNK_SECONDS
    from vjm_ros.logs.opening import recorder_openers

    mcap = args.mcap
    if args.bag is not None:
        if args.mcap is not None:
            raise ConfigurationError("give either --mcap FILE or --bag DIR, not both")
        _prepare_bag(args.bag)
        mcap = args.bag / f"{args.bag.name}_0.mcap"  # named as rosbag2 names it
    return recorder_openers(
        scene.model,
        sim.describe(),
        scene.text,
        mcap=mcap,
        rrd=args.rrd,
        duration=duration,
        rate=sim.settings.rate,
        keys=("--bag" if args.bag is not None else "--mcap", "--rrd"),
        chunk_seconds=MCAP_CHUNK_SECONDS,
        total_samples=samples,
    )


def _report_log_failure(where: str, why: str) -> None:
    print(f"vjm: log {where} could not be written ({why}); recording to it stopped, the run "
          "goes on", file=sys.stderr)


def _run_info(sim, wall: float, cpu: float, waited: float) -> dict:
    """The run's settings and cost, s: ``wall_time``, ``cpu_time`` (the process's CPU time, every
    thread, over the same span: the physics and the outputs written beside it) and
    ``outputs_wait_time`` (the part of ``wall_time`` after the last tick, spent finishing the
    outputs: the blocks still queued, the CSV closed, the logs finalized)."""
    steps = sim.ticks * (sim.settings.substeps if sim.integrator.fixed_step else 1)
    return {**sim.describe(), "wall_time": wall, "cpu_time": cpu, "outputs_wait_time": waited,
            "ticks": sim.ticks, "steps": steps,
            "realtime_factor": (sim.t / wall) if wall > 0 else float("inf"),
            "evaluations": sim.mechanism.evaluations}


PRINTED_KEYS = ("scene", "integrator", "closure", "rate", "substeps", "sim_time", "wall_time",
                "cpu_time", "outputs_wait_time", "steps", "realtime_factor", "max_closure_error",
                "rms_closure_error", "energy_drift", "energy_balance_residual", "finite")
"""Summary keys ``vjm run`` prints without ``--json``, one per line: the contract's keys and the
run's costs beside ``wall_time`` (its CPU time and the wait for the outputs after the last tick)."""


def _print_summary(summary: dict) -> None:
    for k in PRINTED_KEYS:
        v = summary.get(k)
        if isinstance(v, float):
            v = f"{v:.6g}"
        print(f"{k:24s} {v}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
