"""``vjm_sim_node`` over real ROS 2: rates, stamps, trajectories, commands, services, parameters,
and the executable's exit codes.

Each in-process test gets a fresh ``rclpy.Context`` on this process's domain (``conftest.py``);
the node's tick loop runs in a thread (as ``main()`` runs it in the main thread) and a probe node
in the same context listens and commands. Subprocess tests run ``python -m vjm_ros.ros.node`` and
always reap it. Assertions are on simulated time and tick counts, not on wall-clock jitter.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import glob  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray, String  # noqa: E402
from std_srvs.srv import SetBool, Trigger  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402
from waiting import nanoseconds, wait_for

from vjm_ros.ros.node import SimNode, run  # noqa: E402
from vjm_ros.ros.runtime import Spinner  # noqa: E402
from vjm_ros.scene.loader import load_scene  # noqa: E402
from vjm_ros.sim.simulator import SimulationSettings, Simulator

pytestmark = pytest.mark.ros

DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
ROOT = Path(__file__).resolve().parents[1]
NODE = "/vjm_sim_node"
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
ROSOUT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Harness:
    """The simulator node plus a probe node in one fresh context."""

    def __init__(self, **params):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.node = SimNode(
                context=self.ctx,
                parameter_overrides=[Parameter(k, value=v) for k, v in params.items()],
            )
        except Exception:
            rclpy.try_shutdown(context=self.ctx)
            raise
        self.probe = rclpy.create_node("probe", context=self.ctx)
        self.lock = threading.Lock()
        self.got: dict[str, list] = {}
        self.listen("/joint_states", JointState)
        self.listen(f"{NODE}/constraint_forces", Float64MultiArray)
        self.listen(f"{NODE}/energy", Float64MultiArray)
        self.listen(f"{NODE}/events", String)
        self.listen("/clock", Clock)
        self.listen("/diagnostics", DiagnosticArray)
        self.listen(f"{NODE}/markers", MarkerArray)
        for name in self.node.loop.sim.model.force_names:  # closures, then stops
            self.listen(f"{NODE}/closures/{name}/wrench", WrenchStamped)
        self.logs = []
        self.probe.create_subscription(
            Log, "/rosout",
            lambda m: self.logs.append(m) if m.name == "vjm_sim_node" else None, ROSOUT)
        self.efforts = self.probe.create_publisher(Float64MultiArray, f"{NODE}/effort_commands", 10)
        self.named = self.probe.create_publisher(JointState, f"{NODE}/joint_commands", 10)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.probe)
        self.spinner = Spinner(self.executor).start()
        self.thread = None
        self.result = []

    def listen(self, topic, kind, callback=None):
        self.got[topic] = []

        def store(msg):
            with self.lock:
                # arrival times: only for the realtime test's pacing lower bound
                self.got[topic].append((msg, time.monotonic()))
            if callback:
                callback(msg)

        self.probe.create_subscription(kind, topic, store, DEEP)

    def on_joint_state(self, callback):
        """Also call ``callback(msg)`` for every joint state."""
        self.probe.create_subscription(JointState, "/joint_states", callback, DEEP)

    def messages(self, topic):
        with self.lock:
            return [m for m, _ in self.got[topic]]

    def start(self):
        """Wait until every output and command topic is matched, then run the tick loop."""
        def matched():
            outs = all(p.get_subscription_count() > 0 for p in self.node.publishers
                       if p.topic_name in self.got)
            ins = self.efforts.get_subscription_count() > 0 and self.named.get_subscription_count() > 0
            return outs and ins

        wait_for(matched, what="discovery")
        self.thread = threading.Thread(target=lambda: self.result.append(run(self.node)))
        self.thread.start()

    def join(self, timeout=60.0):
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "the tick loop did not stop"
        return self.result[0]

    def call(self, kind, name, request, timeout=10.0):
        client = self.probe.create_client(kind, name)
        try:
            assert client.wait_for_service(timeout_sec=timeout), f"no service {name}"
            future = client.call_async(request)
            wait_for(future.done, timeout, what=f"{name} response")
            return future.result()
        finally:
            self.probe.destroy_client(client)

    def close(self):
        self.node.loop.stop()
        if self.thread is not None:
            self.thread.join(30.0)
        self.spinner.stop()
        self.executor.shutdown()
        self.node.close()
        self.node.destroy_node()
        self.probe.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture
def harness():
    made = []

    def make(**params):
        h = Harness(**params)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()


def stamps_ns(msgs):
    return [nanoseconds(m.header.stamp) for m in msgs]


def plain_simulator(scene_name, rate=1000.0):
    scene = load_scene(scene_name)
    d = scene.defaults
    settings = SimulationSettings(integrator=d.get("integrator", "rk4"), closure="penalty",
                                  rate=rate, substeps=d.get("substeps", 1))
    return Simulator(scene.model, settings, scene.gains)


# ---------------------------------------------------------------- messages: live = log
def fill(msg, values):
    """A ROS message from the nested dict form of :mod:`vjm_ros.logs.messages`."""
    slots = msg.get_fields_and_field_types()
    for key, value in values.items():
        if isinstance(value, dict):
            fill(getattr(msg, key), value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            package, name = slots[key][len("sequence<"):-1].split("/")
            cls = getattr(__import__(f"{package}.msg", fromlist=[name]), name)
            setattr(msg, key, [fill(cls(), v) for v in value])
        else:
            setattr(msg, key, value)
    return msg


def test_live_messages_equal_the_logged_ones():
    from benchmarks import ros_messages as conv
    from vjm_ros.logs import messages as log
    from vjm_ros.ros.conversions import wrench_topic

    sim = plain_simulator("five_bar")
    for _ in range(37):
        sim.advance([1.0, -2.0])
    s = sim.sample()
    ns = log.seconds_to_ns(s.t)
    names = sim.model.joint_names
    assert conv.joint_state(names, s.t, s.q, s.qd, s.effort) == fill(
        JointState(), log.joint_state(names, s, ns))
    layout = conv.labelled_layout(sim.model.closure_names, 3)
    assert conv.constraint_forces(layout, s.closure_force) == fill(
        Float64MultiArray(), log.constraint_forces(sim.model.closure_names, s))
    assert conv.energy(conv.labelled_layout(conv.ENERGY_LABELS, 1), s.energy) == fill(
        Float64MultiArray(), log.energy(s))
    assert conv.wrench(s.closure_force[0], s.t) == fill(WrenchStamped(), log.wrench(s, 0, ns))
    assert conv.clock(s.t) == fill(Clock(), log.clock(ns))
    assert conv.markers(s, s.t) == fill(MarkerArray(), log.markers(s, ns))
    assert wrench_topic("pin") == "~" + log.Topics().wrench("pin")[len(NODE):]


# ---------------------------------------------------------------- rates and stamps
def test_fast_mode_publishes_at_the_configured_rates_with_sim_time_stamps(harness):
    h = harness(rate_hz=500.0, publish_rate_hz=100.0, forces_rate_hz=50.0, realtime=False,
                duration=1.0, publish_clock=False)  # /clock: see the realtime test
    h.start()
    assert h.join() == 0
    wait_for(lambda: len(h.messages("/joint_states")) >= 101, 10.0, "joint states")
    wait_for(lambda: len(h.messages(f"{NODE}/closures/tip_pin/wrench")) >= 51, 10.0, "wrenches")
    js = h.messages("/joint_states")
    assert stamps_ns(js) == [k * 10_000_000 for k in range(101)]  # exactly every 10 ms
    assert js[0].name == ["crank_joint", "coupler_joint", "rocker_joint"]
    wrenches = h.messages(f"{NODE}/closures/tip_pin/wrench")
    assert stamps_ns(wrenches) == [k * 20_000_000 for k in range(51)]
    assert {w.header.frame_id for w in wrenches} == {"world"}
    forces = h.messages(f"{NODE}/constraint_forces")
    assert [(d.label, d.size, d.stride) for d in forces[-1].layout.dim] == [("tip_pin", 3, 3)]
    last = wrenches[-1].wrench
    assert list(forces[-1].data) == [last.force.x, last.force.y, last.torque.z]
    energy = h.messages(f"{NODE}/energy")[-1]
    assert [d.label for d in energy.layout.dim] == ["kinetic", "potential", "constraint", "total"]
    assert energy.data[3] == pytest.approx(sum(energy.data[:3]), abs=1e-9)
    assert not h.messages("/clock")


def test_realtime_mode_follows_the_wall_clock(harness):
    h = harness(rate_hz=200.0, realtime=True, duration=1.5)
    h.start()
    assert h.join() == 0
    wait_for(lambda: len(h.messages("/joint_states")) >= 301, 10.0, "joint states")
    with h.lock:
        arrivals = [t for _, t in h.got["/joint_states"]]
    assert stamps_ns(h.messages("/joint_states")) == [k * 5_000_000 for k in range(301)]
    # Paced, not free-running: a realtime node cannot deliver 1.5 simulated seconds in much less
    # wall time (fast mode does it in ~0.1 s). Only this lower bound is behaviour; how close to
    # 1.5 s a loaded machine keeps is a timing figure (python -m benchmarks.latency).
    assert arrivals[-1] - arrivals[0] > 1.2
    wait_for(lambda: len(h.messages("/clock")) >= 301, 5.0, "/clock")
    assert [nanoseconds(m.clock) for m in h.messages("/clock")] == [k * 5_000_000 for k in range(301)]
    wait_for(lambda: h.messages("/diagnostics"), 5.0, "diagnostics")
    status = h.messages("/diagnostics")[0].status[0]
    assert status.name == "vjm_sim_node: simulation" and status.hardware_id == "four_bar"
    values = {kv.key: kv.value for kv in status.values}
    for key in ("realtime_factor", "late_ticks", "missed_ticks", "max_closure_error",
                "sigma_min", "energy_balance_residual", "lockstep_timeouts"):
        assert key in values
    # Paced, so never well ahead of the wall clock; how far behind a loaded machine falls is a
    # timing figure, not asserted.
    assert float(values["realtime_factor"]) < 1.5
    assert float(values["max_closure_error"]) < 1e-3  # four-bar penalty closure, m
    markers = h.messages(f"{NODE}/markers")
    assert markers and {m.ns for m in markers[-1].markers} == {
        "links", "joints", "constraint_forces", "tip_trace"}


# ---------------------------------------------------------------- trajectories
def test_lockstep_constant_effort_matches_the_plain_simulator(harness):
    h = harness(rate_hz=1000.0, lockstep=True, lockstep_timeout=10.0, command_timeout=0.0,
                realtime=False, duration=0.3)
    h.on_joint_state(lambda msg: h.efforts.publish(Float64MultiArray(data=[3.0])))
    h.start()
    h.efforts.publish(Float64MultiArray(data=[3.0]))  # the answer to t = 0
    assert h.join() == 0
    assert h.node.loop.lockstep_timeouts == 0
    wait_for(lambda: len(h.messages("/joint_states")) >= 301, 10.0, "joint states")
    js = h.messages("/joint_states")[:301]
    ref = plain_simulator("four_bar")
    q, qd = [ref.q.copy()], [ref.qd.copy()]
    for _ in range(300):
        ref.advance([3.0])
        q.append(ref.q.copy())
        qd.append(ref.qd.copy())
    assert stamps_ns(js) == [k * 1_000_000 for k in range(301)]
    assert np.max(np.abs(np.array([m.position for m in js]) - q)) <= 1e-9
    assert np.max(np.abs(np.array([m.velocity for m in js]) - qd)) <= 1e-9
    assert [m.effort[0] for m in js[1:]] == [3.0] * 300


def test_fast_mode_named_command_matches_the_plain_simulator(harness):
    h = harness(scene="five_bar", rate_hz=1000.0, realtime=False, command_timeout=0.0,
                duration=0.2, start_paused=True)
    h.start()
    h.named.publish(JointState(name=["right_base", "left_base"], effort=[-1.0, 2.0]))
    wait_for(lambda: h.node.loop.commands.accepted == 1, 10.0, "the command")
    assert h.call(SetBool, f"{NODE}/pause", SetBool.Request(data=False)).success
    assert h.join() == 0
    wait_for(lambda: nanoseconds(h.messages("/joint_states")[-1].header.stamp) == 200_000_000,
             10.0, "the last joint state")
    js = h.messages("/joint_states")
    assert len(js) >= 190  # fast mode outruns a slow subscriber at times: compare what came
    ref = plain_simulator("five_bar")
    q = {0: ref.q.copy()}
    for k in range(1, 201):
        ref.advance([2.0, -1.0])
        q[k * 1_000_000] = ref.q.copy()
    assert max(np.max(np.abs(np.array(m.position) - q[nanoseconds(m.header.stamp)])) for m in js) <= 1e-9
    assert list(js[-1].effort) == [2.0, 0.0, -1.0, 0.0]  # applied efforts, passive joints zero


# ---------------------------------------------------------------- commands
def log_lines(h, level=Log.WARN):
    return [m.msg for m in list(h.logs) if m.level == level]


def test_command_times_out_to_zero_with_one_warning(harness):
    h = harness(rate_hz=200.0, realtime=True, command_timeout=0.3, duration=1.5)
    h.start()
    wait_for(lambda: len(h.messages("/joint_states")) > 10, 10.0, "joint states")
    h.efforts.publish(Float64MultiArray(data=[5.0]))
    assert h.join() == 0
    wait_for(lambda: any("no valid command" in s for s in log_lines(h)), 10.0, "the warning")
    js = h.messages("/joint_states")
    effort = np.array([m.effort[0] for m in js])
    t = np.array(stamps_ns(js)) * 1e-9
    held = np.flatnonzero(effort == 5.0)
    assert held.size and np.all(effort[held[0]: held[-1] + 1] == 5.0)
    # Held, then dropped after command_timeout (0.3 s of wall time). Paced ticks never run ahead
    # of the wall clock, so the held span in simulated time stays near or below 0.3 s (0.6 s
    # allows a catch-up after a stall); how far below depends on the machine's load, so no lower
    # bound beyond "held at all".
    assert 0.0 < t[held[-1]] - t[held[0]] <= 0.6
    assert np.all(effort[held[-1] + 1:] == 0.0) and held[-1] + 1 < len(js)
    assert h.node.loop.commands.timeouts == 1
    assert sum("no valid command for 0.3 s" in s for s in log_lines(h)) == 1


BAD_COMMANDS = [
    ("array", [1.0, 2.0], "expected 1 value"),
    ("array", [math.nan], "non-finite effort (crank_joint = nan)"),
    ("array", [math.inf], "non-finite effort (crank_joint = inf)"),
    ("named", (["nose"], [1.0]), "unknown joint 'nose'"),
    ("named", (["coupler_joint"], [1.0]), "'coupler_joint' has no actuator"),
    ("named", (["crank_joint", "crank_joint"], [1.0, 1.0]), "more than once"),
    ("named", (["crank_joint"], [1.0, 2.0]), "'name' has 1 entries but 'effort' has 2"),
    ("named", (["crank_joint"], []), "expected joint names with efforts"),
]


def test_bad_commands_are_refused_with_throttled_reasons_and_limits_clamp(harness):
    h = harness(start_paused=True, command_timeout=0.0)
    h.start()
    h.efforts.publish(Float64MultiArray(data=[3.0]))
    wait_for(lambda: h.node.loop.commands.accepted == 1, 10.0, "the valid command")
    for n, (topic, payload, _) in enumerate(BAD_COMMANDS, start=1):
        if topic == "array":
            h.efforts.publish(Float64MultiArray(data=payload))
        else:
            h.named.publish(JointState(name=payload[0], effort=payload[1]))
        wait_for(lambda n=n: h.node.loop.commands.rejected == n, 10.0, f"refusal {n}")
    expected = [w for _, _, w in BAD_COMMANDS]
    wait_for(lambda: all(any(w in s for s in log_lines(h)) for w in expected if "inf" not in w),
             10.0, "the warnings")
    warnings = log_lines(h)
    assert all(s.startswith(("~/effort_commands: command refused:",
                             "~/joint_commands: command refused:")) for s in warnings)
    # The nan and inf commands are one class: the second is held back within a second.
    assert sum("non-finite" in s for s in warnings) == 1
    assert h.node.loop.commands.efforts.tolist() == [3.0]  # nothing refused took effect
    h.efforts.publish(Float64MultiArray(data=[150.0]))
    wait_for(lambda: h.node.loop.commands.accepted == 2, 10.0, "the clamped command")
    assert h.node.loop.commands.efforts.tolist() == [100.0]
    wait_for(lambda: any("150 clamped to 100 (limit 100)" in s for s in log_lines(h)), 10.0,
             "the clamp warning")


def test_bytes_that_hold_no_command_are_refused_naming_the_field(harness):
    """The node reads its commands from their bytes: bytes that hold no such message (sent
    raw by rclpy's publisher) are refused with the field and offset, and change nothing."""
    h = harness(start_paused=True, command_timeout=0.0)
    h.start()
    h.efforts.publish(Float64MultiArray(data=[3.0]))
    wait_for(lambda: h.node.loop.commands.accepted == 1, 10.0, "the valid command")
    truncated = serialize_message(Float64MultiArray(data=[1.0]))[:22]  # half of the double
    h.efforts.publish(truncated)
    wait_for(lambda: h.node.loop.commands.rejected == 1, 10.0, "the truncated command")
    h.named.publish(b"\x00\x07\x00\x00" + bytes(8))  # not plain CDR
    wait_for(lambda: h.node.loop.commands.rejected == 2, 10.0, "the foreign bytes")
    expected = ["~/effort_commands: command refused: std_msgs/Float64MultiArray: data needs 8 "
                "bytes at byte 20, the message has 22",
                "~/joint_commands: command refused: sensor_msgs/JointState: expected a plain CDR "
                "encapsulation header"]
    wait_for(lambda: all(any(w in s for s in log_lines(h)) for w in expected), 10.0,
             "the warnings")
    assert h.node.loop.commands.efforts.tolist() == [3.0]


def diagnostic_values(msg):
    return {kv.key: kv.value for kv in msg.status[0].values}


def test_commands_beyond_the_scenes_sizes_are_refused_unread_and_counted(harness):
    """While the node ticks (the tick loop reads the commands itself), a valid command whose
    layout holds 1000 dimensions and a joint command of 5000 names are refused from their
    counts, with a warning that says so, and counted in /diagnostics; a normal command then
    still applies."""
    from std_msgs.msg import MultiArrayDimension

    h = harness(command_timeout=0.0)
    h.start()
    wait_for(lambda: len(h.messages("/joint_states")) > 5, 10.0, "the ticks")
    wide = Float64MultiArray(data=[3.0])
    wide.layout.dim = [MultiArrayDimension() for _ in range(1000)]
    h.efforts.publish(wide)
    h.named.publish(JointState(name=["crank_joint"] * 5000, effort=[1.0] * 5000))
    wait_for(lambda: h.node.loop.commands.oversize == 2, 10.0, "the two refusals")
    h.efforts.publish(Float64MultiArray(data=[3.0]))
    wait_for(lambda: h.node.loop.commands.accepted == 1, 10.0, "the normal command")
    assert h.node.loop.commands.rejected == 2
    counted = {"refused_oversize_commands": "2", "commands_rejected": "2",
               "commands_accepted": "1"}
    wait_for(lambda: any(counted.items() <= diagnostic_values(m).items()
                         for m in h.messages("/diagnostics")), 10.0, "the counts in /diagnostics")
    expected = ["~/effort_commands: command refused: std_msgs/Float64MultiArray: layout.dim holds "
                "1000 dimensions, more than the 8 a command to this scene can need (refused "
                "unread)",
                "~/joint_commands: command refused: sensor_msgs/JointState: name holds 5000 "
                "names, more than the"]
    wait_for(lambda: all(any(w in s for s in log_lines(h)) for w in expected), 10.0,
             "the warnings")
    assert h.node.loop.commands.efforts.tolist() == [3.0]


# ---------------------------------------------------------------- services
def test_pause_step_reset_services(harness):
    # 100 Hz ticks (slow enough to pause between them); two substeps keep the thesis gains
    # inside rk4's stability bound (one 10 ms step is refused by the stiffness check).
    h = harness(rate_hz=100.0, substeps=2, realtime=True)
    h.start()
    wait_for(lambda: len(h.messages("/joint_states")) > 5, 10.0, "joint states")
    res = h.call(SetBool, f"{NODE}/pause", SetBool.Request(data=True))
    assert res.success and res.message.startswith("paused at t = ")
    # The pause takes effect at a tick boundary and names the time of the last state published:
    # wait until that state has arrived (however long a loaded machine takes to deliver it), then
    # nothing more may come while paused; 0.3 s is 30 periods.
    paused_ns = round(float(res.message.split("t = ")[1].split()[0].rstrip("s")) * 1e9)
    # (the message prints 6 significant digits; ticks are 10 ms apart, so 1 ms tells them apart)
    wait_for(lambda: any(abs(nanoseconds(m.header.stamp) - paused_ns) < 1_000_000
                         for m in h.messages("/joint_states")), 10.0, "the last state before pause")
    count = len(h.messages("/joint_states"))
    time.sleep(0.3)
    assert len(h.messages("/joint_states")) == count  # nothing while paused
    t_last = nanoseconds(h.messages("/joint_states")[-1].header.stamp)
    res = h.call(Trigger, f"{NODE}/step", Trigger.Request())
    assert res.success and res.message == f"stepped to t = {(t_last + 10_000_000) * 1e-9:.6g} s"
    wait_for(lambda: len(h.messages("/joint_states")) == count + 1, 10.0, "the stepped state")
    assert nanoseconds(h.messages("/joint_states")[-1].header.stamp) == t_last + 10_000_000
    res = h.call(Trigger, f"{NODE}/reset", Trigger.Request())
    assert res.success and "reset to the initial state" in res.message
    wait_for(lambda: len(h.messages("/joint_states")) == count + 2, 10.0, "the reset state")
    first, latest = h.messages("/joint_states")[0], h.messages("/joint_states")[-1]
    # Back to the initial state, but simulated time goes on: one tick after the last stamp.
    restart = t_last + 2 * 10_000_000
    assert nanoseconds(latest.header.stamp) == restart
    assert list(latest.position) == list(first.position)
    assert res.message.endswith(f"goes on from t = {restart * 1e-9:.6g} s")
    assert h.call(SetBool, f"{NODE}/pause", SetBool.Request(data=False)).success
    wait_for(lambda: len(h.messages("/joint_states")) > count + 5, 10.0, "running again")
    assert stamps_ns(h.messages("/joint_states")[count + 1: count + 4]) == [
        restart, restart + 10_000_000, restart + 20_000_000]
    clocks = [nanoseconds(m.clock) for m in h.messages("/clock")]
    assert clocks and all(b > a for a, b in zip(clocks, clocks[1:], strict=False))
    res = h.call(Trigger, f"{NODE}/step", Trigger.Request())
    assert not res.success and "not paused" in res.message
    events = [m.data.split(":")[0] for m in h.messages(f"{NODE}/events")]
    assert events[:4] == ["paused", "stepped", "reset", "resumed"]


def test_parameters_are_validated_at_run_time(harness):
    h = harness(start_paused=True)
    h.start()

    def set_param(name, value):
        request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
        return h.call(SetParameters, f"{NODE}/set_parameters", request).results[0]

    refused = [
        ("rate_hz", -5.0, "rate_hz"),
        ("integrator", "rk5", "integrator: expected one of"),
        ("kp", 1e9, "omega_n"),
        ("publish_rate_hz", 5000.0, "publish_rate_hz: expected at most the tick rate 1000"),
        ("realtime", "yes", "Wrong parameter type"),  # refused by rclpy itself
        ("scene", "no_such_scene", "no such scene"),
        ("mcap", "/tmp/x.mcap", "read-only"),
    ]
    for name, value, words in refused:
        result = set_param(name, value)
        assert not result.successful and words in result.reason, (name, result.reason)
    assert h.node.loop.sim.dt == 0.001
    assert set_param("command_timeout", 2.0).successful
    assert h.node.loop.commands.timeout == 2.0
    assert set_param("rate_hz", 500).successful  # an integer is accepted for a float
    assert h.node.loop.sim.dt == 0.001  # applies at the next reset
    assert h.call(Trigger, f"{NODE}/reset", Trigger.Request()).success
    assert h.node.loop.sim.dt == 0.002
    # simulated time goes on: the new episode starts one (new) tick after t = 0, the step ends
    # one tick later
    assert h.call(Trigger, f"{NODE}/step", Trigger.Request()).message == "stepped to t = 0.004 s"
    assert set_param("scene", "five_bar").successful  # another mechanism at the next reset
    assert h.call(Trigger, f"{NODE}/reset", Trigger.Request()).success
    wait_for(lambda: h.messages("/joint_states")[-1].name[0] == "left_base", 10.0, "five_bar")
    assert h.node.loop.commands.actuator_names == ["left_base", "right_base"]
    assert f"{NODE}/closures/pin/wrench" in {p.topic_name for p in h.node.publishers}


def test_publish_clock_off_drops_the_clock_publisher_and_on_brings_it_back(harness):
    """A simulator with ``publish_clock`` false holds no ``/clock`` publisher (so that, among
    several simulators, the graph shows the one that owns the clock)."""
    h = harness(rate_hz=100.0, substeps=2)  # two substeps: the thesis gains at 100 Hz (rk4)
    h.start()

    def set_clock(value):
        request = SetParameters.Request(
            parameters=[Parameter("publish_clock", value=value).to_parameter_msg()])
        return h.call(SetParameters, f"{NODE}/set_parameters", request).results[0]

    def clock_publishers():
        return [(i.node_namespace, i.node_name)
                for i in h.probe.get_publishers_info_by_topic("/clock")]

    wait_for(lambda: len(h.messages("/clock")) > 5, 10.0, "/clock")
    assert clock_publishers() == [("/", "vjm_sim_node")]
    assert set_clock(False).successful
    wait_for(lambda: not clock_publishers(), 10.0, "the /clock publisher to go")
    count = len(h.messages("/clock"))
    assert set_clock(True).successful
    wait_for(lambda: len(h.messages("/clock")) > count + 5, 10.0, "/clock again")
    assert clock_publishers() == [("/", "vjm_sim_node")]
    clocks = [nanoseconds(m.clock) for m in h.messages("/clock")]
    assert all(b > a for a, b in zip(clocks, clocks[1:], strict=False))


# ---------------------------------------------------------------- the executable
def test_config_file_lists_every_parameter_with_a_valid_value():
    import yaml

    from vjm_ros.realtime.parameters import PARAMETERS, NodeConfig

    values = yaml.safe_load((ROOT / "config" / "sim_node.yaml").read_text())
    values = values["/**"]["ros__parameters"]
    assert list(values) == [p.name for p in PARAMETERS]
    NodeConfig.from_values(values)


def test_launch_file_compiles_and_agrees_with_the_node():
    """The launch file's default scene is the node's (and the config file's), and it declares the
    arguments users rely on, using only DeclareLaunchArgument (no distro-specific actions)."""
    import ast

    import yaml

    from vjm_ros.realtime.parameters import PARAMETERS

    source = (ROOT / "launch" / "sim.launch.py").read_text()
    namespace = {}
    exec(compile(source, "sim.launch.py", "exec"), namespace)  # defines; launch is not imported
    default = next(p.default for p in PARAMETERS if p.name == "scene")
    assert namespace["DEFAULT_SCENE"] == default
    config = yaml.safe_load((ROOT / "config" / "sim_node.yaml").read_text())
    assert config["/**"]["ros__parameters"]["scene"] == default
    declared = {
        node.args[0].value
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "DeclareLaunchArgument"
    }
    assert {"scene", "namespace", "use_sim_time", "controller", "lockstep", "rate_hz"} <= declared
    assert "SetEnvironmentVariable" not in source


def node_process(*params, args=()):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
               PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args", *args]
    for p in params:
        cmd += ["-p", p]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def finish(proc, timeout=60.0):
    try:
        out, _ = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, out


def orphaned_shm(before):
    """Fast DDS shared-memory files created since ``before`` that no live process maps."""
    now = set(glob.glob("/dev/shm/fastdds_*")) | set(glob.glob("/dev/shm/sem.fastdds_*"))
    held = set()
    for maps in glob.glob("/proc/[0-9]*/maps"):
        try:
            held.update(re.findall(r"/dev/shm/\S+", Path(maps).read_text()))
        except OSError:
            continue
    # Lock files (``*_el``, ``*_sl``) are never mapped, and may belong to other live participants
    # on this machine; a leaked participant also leaves its (mappable) data segment, checked here.
    return {
        f
        for f in now - before
        if f not in held and not f.startswith("/dev/shm/sem.") and not f.endswith(("_el", "_sl"))
    }


def summary_of(output):
    match = re.search(r"summary (\{.*\})", output)
    assert match, output
    return json.loads(match.group(1))


class Listener:
    """A probe in its own context, for the subprocess tests."""

    def __init__(self, topics):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("listener", context=self.ctx)
        self.count = {t: 0 for t in topics}
        for topic, kind in topics.items():
            self.node.create_subscription(
                kind, topic, lambda m, t=topic: self.count.__setitem__(t, self.count[t] + 1), DEEP)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor).start()

    def close(self):
        self.spinner.stop()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def test_executable_runs_five_bar_for_its_duration_while_another_process_listens():
    listener = Listener({"/joint_states": JointState, f"{NODE}/closures/pin/wrench": WrenchStamped})
    before = set(glob.glob("/dev/shm/fastdds_*"))
    try:
        # 4 s in realtime: long enough for the listener to match both publishers mid-run, also
        # on a loaded machine (a CI run saw none of 1500 ticks' messages arrive in 1.5 s)
        code, out = finish(node_process("scene:=five_bar", "duration:=4.0"))
        wait_for(lambda: listener.count[f"{NODE}/closures/pin/wrench"] > 0, 5.0,
                 f"wrenches (received {listener.count}; node output:\n{out})")
    finally:
        listener.close()
    assert code == 0, out
    summary = summary_of(out)
    assert summary["reason"] == "duration" and summary["ticks"] == 4000
    # some of the ticks at least: what the listener receives once it has matched
    assert listener.count["/joint_states"] > 150 and listener.count[f"{NODE}/closures/pin/wrench"] > 15
    assert not orphaned_shm(before)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signals_stop_the_executable_cleanly(sig, tmp_path):
    listener = Listener({"/joint_states": JointState})
    before = set(glob.glob("/dev/shm/fastdds_*"))
    mcap = tmp_path / "run.mcap"
    proc = node_process("realtime:=true", f"mcap:={mcap}")
    try:
        wait_for(lambda: listener.count["/joint_states"] > 100, 30.0, "the node to run")
        proc.send_signal(sig)
        code, out = finish(proc, 20.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        listener.close()
    assert code == 0, out
    ticks = summary_of(out)["ticks"]
    assert summary_of(out)["reason"] == "stopped"
    assert not orphaned_shm(before)
    from mcap.reader import make_reader

    with mcap.open("rb") as f:  # finalized: the summary section is there
        reader = make_reader(f)
        stats = reader.get_summary().statistics
        assert stats.channel_message_counts and stats.message_count > ticks


@pytest.mark.parametrize(
    "params, words",
    [
        (["integrator:=rk5"], "integrator: expected one of"),
        (["kp:=1e9", "kv:=0.0"], "beyond the stability bound"),
        (["scene:=/no/such.yaml"], "no such scene or file"),
        (["substeps:=2.5"], "substeps"),
    ],
)
def test_bad_configuration_exits_with_code_2(params, words):
    code, out = finish(node_process(*params))
    assert code == 2 and words in out, out


def test_divergence_exits_with_code_3():
    code, out = finish(node_process("kp:=10.0", "kv:=0.0", "realtime:=false"))
    assert code == 3, out
    assert "simulation diverged" in out and "tip_pin" in out


@pytest.mark.parametrize("namespace", ["", "/lab/arm"])
def test_params_file_loads_and_logs_are_written(tmp_path, namespace):
    """The shipped params file applies to the node, also under a namespace (launch's
    ``namespace:=``): a copy that changes one value (the scene) must change the run."""
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    text = (ROOT / "config" / "sim_node.yaml").read_text()
    edited = re.sub(r"(?m)^(\s+scene:) four_bar\b", r"\1 five_bar", text)
    assert edited != text
    params = tmp_path / "sim_node.yaml"
    params.write_text(edited)
    remap = ("-r", f"__ns:={namespace}") if namespace else ()
    code, out = finish(node_process(
        "duration:=0.2", "realtime:=false", f"mcap:={mcap}", f"rrd:={rrd}", "realtime_priority:=10",
        args=(*remap, "--params-file", str(params))))
    assert code == 0, out
    assert "tick loop at SCHED_FIFO priority 10" in out or "realtime_priority 10 not granted" in out
    summary = summary_of(out)
    assert summary["scene"] == "five_bar" and summary["ticks"] == 200
    assert rrd.stat().st_size > 0
    from mcap.reader import make_reader

    with mcap.open("rb") as f:
        reader = make_reader(f)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        joint_states = f"{namespace}/joint_states"
        assert joint_states in topics
        assert sum(1 for _ in reader.iter_messages(topics=[joint_states])) == 201


def test_a_log_that_fills_up_is_given_up_while_the_node_runs_on():
    code, out = finish(node_process("realtime:=false", "duration:=0.5", "mcap:=/dev/full"))
    assert code == 0, out
    assert summary_of(out)["ticks"] == 500  # the simulation went on without the log
    assert re.search(r"WARN.*log /dev/full could not be written \(No space left on device\); "
                     r"recording to it stopped", out), out
