"""What this machine lets a 1 kHz loop keep: the node's pacer with nothing to do per tick.

``python -m benchmarks.pacing_floor [--seconds 10] [--rate 1000] [--repeats 1]`` runs
:class:`vjm_ros.realtime.pacing.Pacer`, the pacer of ``vjm_sim_node``, in realtime at normal
priority with an empty tick, and counts its late and missed ticks as the node counts its own.
Whatever such a loop misses, the node misses too, whatever its tick costs: a tick that starts a
period or more after its deadline is missed (:mod:`vjm_ros.realtime.pacing`), and every tick after
a stall of the process counts until the loop has caught up. On a machine that holds the process
off its core for milliseconds at a time (a virtual machine on a busy host, for one), these stalls
alone can exceed the live target of :mod:`benchmarks.live_loop` (at most 0.1 % of the
ticks missed); that study runs this loop before each of its scenes so that its figures can be
read against the machine's.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

from vjm_ros.realtime.pacing import Pacer


def measure(seconds: float = 10.0, rate: float = 1000.0, *,
            clock: Callable[[], float] = time.perf_counter,
            sleep: Callable[[float], None] = time.sleep) -> dict:
    """Run the pacer with an empty tick for ``seconds`` of wall time at ``rate``.

    Parameters
    ----------
    seconds : float
        Wall time, s.
    rate : float
        Ticks per second, Hz.
    clock, sleep : callable
        Monotonic time (s) and ``sleep(seconds)`` (the real ones by default).

    Returns
    -------
    dict
        ``ticks``, ``missed_ticks`` and ``late_ticks`` (as the node counts them),
        ``missed_share`` (of the ticks), ``max_lateness_ms`` (latest start, ms), ``rate`` (Hz)
        and ``seconds``.
    """
    if not (seconds > 0 and rate > 0):
        raise ValueError(f"seconds and rate: expected positive numbers, found {seconds!r} "
                         f"and {rate!r}")
    pacer = Pacer(1.0 / rate, True, clock=clock, sleep=sleep)
    ticks = int(round(seconds * rate))
    for _ in range(ticks):
        pacer.wait()
    s = pacer.stats
    return {"ticks": s.ticks, "missed_ticks": s.missed, "late_ticks": s.late,
            "missed_share": s.missed / max(s.ticks, 1), "max_lateness_ms": 1e3 * s.max_lateness,
            "rate": float(rate), "seconds": float(seconds)}


def describe(row: dict) -> str:
    """One line of text for a row of :func:`measure`."""
    return (f"pacing floor: the node's pacer with an empty tick missed {row['missed_ticks']} of "
            f"{row['ticks']} ticks ({100 * row['missed_share']:.2f} %) at {row['rate']:g} Hz, "
            f"the latest {row['max_lateness_ms']:.1f} ms late")


def main(argv: list[str] | None = None) -> int:
    """Command line entry: measure and print one line per repeat (or JSON)."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.pacing_floor",
                                description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=10.0, help="wall time per run, s (10)")
    p.add_argument("--rate", type=float, default=1000.0, help="ticks per second, Hz (1000)")
    p.add_argument("--repeats", type=int, default=1, help="runs, one after the other (1)")
    p.add_argument("--json", action="store_true", help="rows as JSON on the last line")
    args = p.parse_args(argv)
    rows = []
    for _ in range(max(args.repeats, 1)):
        rows.append(measure(args.seconds, args.rate))
        print(describe(rows[-1]), flush=True)
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
