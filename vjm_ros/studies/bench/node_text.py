"""The live node's section of ``docs/accuracy.md``: figures of the node studies, measured by hand.

The bench does not run a ROS node; these figures come from ``python -m
vjm_ros.studies.node_cost`` and ``python -m vjm_ros.studies.live_loop``, run in one sitting
(the code before and after the node's per-tick work was cut, alternating), and are kept here so
that the page keeps them when the bench rewrites it. Rerun both studies to refresh them.
"""

from __future__ import annotations


def node_text() -> list[str]:
    """Markdown lines of the section (ends with a blank line)."""
    return [
        "## Live node",
        "",
        "Measured with `python -m vjm_ros.studies.node_cost` (fast mode, 5 simulated s at 1 kHz, "
        "one subscriber process on every topic) and `python -m vjm_ros.studies.live_loop` "
        "(realtime at 1 kHz, normal priority, 10 s, a 1 kHz controller process that subscribes "
        "to every topic and answers each joint state) on this 2-core machine while other jobs "
        "ran on it; *before* is the node without the changes listed here, run alternately with "
        "*after*, 3 runs of each (node_cost at load average 3.7-6.0, live_loop at 2.2-4.8).",
        "",
        "- **CPU per tick against its floor** (node / (physics + bare rclpy publishing of the "
        "same messages), target at most 1.3): after 1.20-1.79 on four_bar, 1.28-1.60 on "
        "five_bar, 0.92-1.26 on three_chain; before 2.24-2.40, 1.80-2.45, 2.39-2.47. The node's "
        "CPU per tick fell from 134-192 µs to 59-110 µs; physics is 9-11 µs and bare "
        "publishing of the 5-6 messages 35-88 µs of the same runs (its spread is most of the "
        "ratio's).",
        "- **Where the rest goes** (five_bar, fast mode, CPU per tick of each thread in one "
        "run): the tick thread 68-96 µs, of which physics 10 µs and the loop's own Python about "
        "12 µs (23.5 µs before; measured with publishing stubbed out), the rest rclpy and Fast "
        "DDS publishing; Fast DDS's event thread 8-14 µs; the executor thread under 1 µs. "
        "Publishing the same bytes in a tight loop costs about half as much per message as "
        "between ticks: the bare-publish floor is a lower bound the node cannot reach.",
        "- **Live, 1 kHz controller in the loop** (four_bar, six_bar, double_slider, five_bar, "
        "three_chain; targets: at most 0.1 % missed ticks, median command lag at most 2 ticks, "
        "at least 95 % of commands applied): after 0.10-9.7 % missed ticks (median of the 15 "
        "scene runs 4.9 %), median lag 1 tick in every run (p99 1-9), 76-99.5 % applied; before "
        "0.19-74 % missed (median 13.5 %), median lag 1-62 ticks (p99 1-482), 55-99 % "
        "applied. Only one scene run met the missed-tick target (double_slider, 0.10 %): a "
        "missed tick is the tick thread waiting for a core, and the two cores carry the other "
        "jobs, the controller's executor (7 topics at 1 kHz) and the node. The node's executor "
        "thread spent 238 µs per command before (a quarter of a core at 1 kHz) and 10 µs after "
        "(the tick loop takes the commands itself); the tick thread's ~260 µs per tick is "
        "mostly the spin to the deadline (the last 0.2 ms before it).",
        "",
    ]
