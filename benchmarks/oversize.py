"""A live ``vjm_sim_node`` under a stream of oversized commands; re-run with
``python -m benchmarks.oversize``.

The stream: a valid ``std_msgs/Float64MultiArray`` on ``~/effort_commands`` whose layout holds
``dims`` empty dimensions (200 000 by default: 3.2 MB, 16 bytes each) besides one value per
actuator, published ``hz`` times a second (5 by default) by a probe in this process. The node's
own ``~/effort_commands`` reader (``ros/command_wire.py``) gets every message on the tick loop's
thread, so the cost of reading one is the tick loop's.

The node runs twice, realtime at ``rate`` Hz for ``seconds`` of wall time from its first tick
(then SIGINT), with ``wait_for_command``: once alone, once under the stream. Each run starts ticking on a small
valid command (sent every 50 ms until the first tick shows); the stream, if any, follows at
once. From the node's exit summary, for each
run: the realtime factor while ticking (simulated time over the wall time from the first tick),
late and missed ticks, the largest lateness of a tick, and the commands accepted, refused, and
refused for their size before reading them (``refused_oversize_commands``, where the node
counts it).

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python -m benchmarks.oversize [--scene five_bar] [--json]

Numbers depend on what else runs on the machine: the 1-minute load average is printed with them.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import struct
import sys
import threading
import time
from collections.abc import Sequence

from vjm_ros.scene.loader import load_scene

DIMS = 200_000
"""Empty layout dimensions of a stream message (3.2 MB)."""
STREAM_HZ = 5.0
"""Stream messages per second."""
START_VALUE = 0.0
"""The efforts of the command that starts the ticks (and of every stream message), N m or N."""


def wide_layout_command(dims: int, values: Sequence[float], label: str = "") -> bytes:
    """A serialized ``std_msgs/Float64MultiArray`` (plain CDR, little-endian) whose layout holds
    ``dims`` dimensions, each labelled ``label`` with size and stride 0, and whose data are
    ``values``, built without a Python object per dimension: as long as what rclpy's
    ``serialize_message`` writes for that message, which rclpy reads back as that message
    (test/test_command_bounds.py); padding bytes are zero.

    Returns
    -------
    bytes
        ``4 + 4 + dims * (4 + pad4(len(label) + 1) + 8) + 4 + 4``, padded to a multiple of 8
        after the header, ``+ 8 * len(values)``.
    """
    text = label.encode("utf-8") + b"\x00"
    text += bytes(-len(text) % 4)
    one = struct.pack("<I", len(label.encode("utf-8")) + 1) + text + struct.pack("<II", 0, 0)
    body = struct.pack("<I", dims) + one * dims + struct.pack("<II", 0, len(values))
    body += bytes(-len(body) % 8)  # aligned for the doubles, also when there are none
    return b"\x00\x01\x00\x00" + body + struct.pack(f"<{len(values)}d", *values)


class Stream:
    """Publishes ``data`` on the probe's ``~/effort_commands`` ``hz`` times a second until
    stopped, in a thread of its own."""

    def __init__(self, probe, data: bytes, hz: float):
        self.probe, self.data, self.period = probe, data, 1.0 / hz
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="oversize_stream", daemon=True)

    def start(self) -> Stream:
        self._thread.start()
        return self

    def _run(self) -> None:
        t0 = time.monotonic()
        while not self._stop.is_set():
            self.probe.efforts.publish(self.data)  # serialized bytes: published as they are
            self.sent += 1
            self._stop.wait(max(0.0, t0 + self.sent * self.period - time.monotonic()))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def run_once(scene: str, rate: float, seconds: float, stream: bytes | None, hz: float,
             extra: Sequence[str] = ()) -> dict:
    """Run the node once, with the stream if ``stream`` holds its bytes; its figures."""
    import subprocess

    from benchmarks.latency import node_command, node_summary
    from benchmarks.probes import GraphProbe

    n = len(load_scene(scene).model.actuator_names)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    cmd = node_command(scene, rate, 0.0, True, ["wait_for_command:=true", *extra])
    flow = None
    ticking = threading.Event()

    def on_state(msg) -> None:
        if msg.header.stamp.sec or msg.header.stamp.nanosec:  # a state after the first tick
            ticking.set()

    with GraphProbe("vjm_oversize_probe", commands=True, on_state=on_state, depth=10) as probe:
        node = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        try:
            start = time.monotonic()
            while not probe.commands_matched():
                if node.poll() is not None or time.monotonic() - start > 60.0:  # hang guard
                    raise RuntimeError("the node's command topics never matched:\n"
                                       + node.communicate()[0])
                time.sleep(0.01)
            # the command that starts the ticks, again until they run (a message sent as the
            # topics match may reach a subscriber that has not matched the writer yet)
            while not ticking.is_set():
                if node.poll() is not None or time.monotonic() - start > 120.0:  # hang guard
                    raise RuntimeError("the node did not start:\n" + node.communicate()[0])
                probe.publish_efforts([START_VALUE] * n)
                ticking.wait(0.05)
            if stream is not None:
                flow = Stream(probe, stream, hz).start()
            time.sleep(seconds)
            if flow is not None:
                flow.stop()
            node.send_signal(signal.SIGINT)
            out, _ = node.communicate(timeout=60.0)  # hang guard
        finally:
            if flow is not None:
                flow.stop()
            if node.poll() is None:
                node.kill()
                node.communicate()
    summary = node_summary(node.returncode, out)
    ticking = summary["ticking_wall_time"]
    return {
        "stream": stream is not None,
        "stream_bytes": len(stream) if stream is not None else 0,
        "stream_sent": flow.sent if flow is not None else 0,
        "ticks": summary["ticks"],
        "sim_time": summary["sim_time"],
        "ticking_wall_time": ticking,
        "realtime_factor": summary["sim_time"] / ticking if ticking > 0 else float("nan"),
        "late_ticks": summary["late_ticks"],
        "missed_ticks": summary["missed_ticks"],
        "max_lateness_ms": 1e3 * summary["max_lateness"],
        "commands_accepted": summary["commands_accepted"],
        "commands_rejected": summary["commands_rejected"],
        "refused_oversize_commands": summary.get("refused_oversize_commands"),
    }


def measure(scene: str = "five_bar", seconds: float = 10.0, rate: float = 1000.0,
            hz: float = STREAM_HZ, dims: int = DIMS, extra: Sequence[str] = ()) -> dict:
    """The node alone, then under the stream.

    Parameters
    ----------
    scene : str
        A scene with actuators.
    seconds : float
        Wall time of each run from its first tick, s.
    rate : float
        Tick rate, Hz.
    hz : float
        Stream messages per second.
    dims : int
        Empty layout dimensions of each stream message.
    extra : sequence of str
        More node parameters ``name:=value``.

    Returns
    -------
    dict
        ``alone`` and ``stream``: the figures of :func:`run_once`; the load average around.
    """
    n = len(load_scene(scene).model.actuator_names)
    data = wide_layout_command(dims, [START_VALUE] * n)
    row = {"scene": scene, "seconds": seconds, "rate_hz": rate, "stream_hz": hz, "dims": dims,
           "load_1min": os.getloadavg()[0]}
    row["alone"] = run_once(scene, rate, seconds, None, hz, extra)
    row["stream"] = run_once(scene, rate, seconds, data, hz, extra)
    row["load_1min_end"] = os.getloadavg()[0]
    return row


def _format(row: dict) -> str:
    def one(r: dict) -> str:
        oversize = r["refused_oversize_commands"]
        return (f"realtime factor {r['realtime_factor']:.3f} over {r['ticks']} ticks, late "
                f"{r['late_ticks']}, missed {r['missed_ticks']}, max lateness "
                f"{r['max_lateness_ms']:.1f} ms; commands accepted {r['commands_accepted']}, "
                f"refused {r['commands_rejected']}"
                + (f" ({oversize} for their size)" if oversize is not None else ""))

    s = row["stream"]
    return (f"{row['scene']} at {row['rate_hz']:g} Hz, {row['seconds']:g} s each:\n"
            f"  alone: {one(row['alone'])}\n"
            f"  {s['stream_sent']} commands of {s['stream_bytes'] / 1e6:.1f} MB "
            f"({row['dims']} layout dimensions) at {row['stream_hz']:g} Hz: {one(s)}\n"
            f"  load {row['load_1min']:.2f}-{row['load_1min_end']:.2f}")


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module documentation."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    parser = argparse.ArgumentParser(prog="python -m benchmarks.oversize",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="five_bar", help="scene with actuators (five_bar)")
    parser.add_argument("--seconds", type=float, default=10.0,
                        help="wall time of each run from its first tick, s (10)")
    parser.add_argument("--rate", type=float, default=1000.0, help="node tick rate, Hz (1000)")
    parser.add_argument("--hz", type=float, default=STREAM_HZ,
                        help=f"stream messages per second ({STREAM_HZ:g})")
    parser.add_argument("--dims", type=int, default=DIMS,
                        help=f"empty layout dimensions per message ({DIMS})")
    parser.add_argument("-p", "--param", action="append", default=[],
                        help="node parameter name:=value (repeatable)")
    parser.add_argument("--json", action="store_true",
                        help="print the figures as JSON on the last line")
    args = parser.parse_args(argv)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    row = measure(args.scene, args.seconds, args.rate, args.hz, args.dims, args.param)
    print(_format(row), flush=True)
    if args.json:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
