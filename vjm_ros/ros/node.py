"""``vjm_sim_node``: a scene simulated at a fixed rate, served over ROS 2.

Run it::

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST vjm_sim_node --ros-args -p scene:=five_bar -p duration:=5.0
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python -m vjm_ros.ros.node --ros-args --params-file config/sim_node.yaml

Parameters: :data:`vjm_ros.realtime.parameters.PARAMETERS` (each declared with its description and range;
``config/sim_node.yaml`` lists them all). Topics (``~`` is ``/vjm_sim_node``):

==============================  ========================================  =========================
topic                           type                                      when
==============================  ========================================  =========================
``joint_states`` (relative)     ``sensor_msgs/JointState``                every tick, or
                                                                          ``publish_rate_hz``
``~/constraint_forces``         ``std_msgs/Float64MultiArray``            every tick, or
                                                                          ``forces_rate_hz``
``~/closures/<name>/wrench``    ``geometry_msgs/WrenchStamped``           same
``~/energy``                    ``std_msgs/Float64MultiArray``            same
``/clock``                      ``rosgraph_msgs/Clock``                   every tick (one simulator
                                                                          of a graph; see
                                                                          :mod:`~.clock_owner`)
``~/markers``                   ``visualization_msgs/MarkerArray``        ``marker_rate_hz`` (wall)
``/diagnostics``                ``diagnostic_msgs/DiagnosticArray``       1 Hz (wall)
``~/events``                    ``std_msgs/String`` (transient local,     pause, step, reset, timeouts
                                depth 100)
``~/scene_description``         ``std_msgs/String`` (transient local)     at start and new scenes
``robot_description`` (relative) ``std_msgs/String`` (transient local)    same: the scene's URDF
``~/effort_commands`` (in)      ``std_msgs/Float64MultiArray``            one value per actuator
``~/joint_commands`` (in)       ``sensor_msgs/JointState``                efforts by joint name
``~/external_wrench`` (in)      ``geometry_msgs/WrenchStamped``           at a named point
==============================  ========================================  =========================

A scene with ``sensors`` publishes on ``joint_states`` what its sensors measure, and the exact
state beside it on ``~/ground_truth/joint_states`` (``sensor_msgs/JointState``, same times).
The stop of a joint with a ``range`` is published as a closure named ``<joint>_stop``.

Message layouts: :mod:`vjm_ros.ros.conversions` (the per-tick ones published as serialized bytes, :mod:`vjm_ros.ros.wire`). Header stamps are simulated time, which only
increases (also across ``~/reset``); the node itself runs on the wall clock (it publishes
``/clock`` but does not use it). Services: ``~/pause``
(``std_srvs/SetBool``), ``~/step`` (``std_srvs/Trigger``, one tick while paused), ``~/reset``
(``std_srvs/Trigger``, back to the initial state; settings changed since take effect).

A controller that starts with the simulator should be paired with ``-p wait_for_command:=true``
(the initial state is held, and republished, until its first command arrives) or with
``lockstep`` (every tick waits for its command).

Threads: the tick loop (:class:`~vjm_ros.realtime.loop.TickLoop`) owns the main thread; a background
thread spins the executor with ``spin_once(timeout_sec=0.05)`` for the services and parameters.
The tick loop takes the commands itself at the start of each tick while it ticks freely; while
paused, holding for the first command or in lockstep, the executor delivers them
(:class:`~vjm_ros.ros.runtime.PolledGroup`).

Exit codes:

* 0: ``duration`` reached, or stopped by SIGINT or SIGTERM (logs finalized);
* 1: unexpected error (traceback printed);
* 2: bad configuration (parameter, scene, penalty gains the integrator cannot carry, log file);
* 3: the simulation diverged (the message names the time, the closure and the likely cause).
"""

from __future__ import annotations

import json
import math
import sys
import time
import traceback
from typing import TYPE_CHECKING

import numpy as np
import rclpy
import rclpy.exceptions
import rclpy.logging
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import (
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from vjm_ros.core.errors import ConfigurationError, DivergenceError, VjmError
from vjm_ros.formats.urdf_out import scene_urdf
from vjm_ros.logs import events
from vjm_ros.logs.opening import open_recorders as open_log_recorders
from vjm_ros.realtime.commands import CommandBuffer, Throttle, Verdict
from vjm_ros.realtime.loop import LoopOptions, TickLoop
from vjm_ros.realtime.monitor import ERROR, assess
from vjm_ros.realtime.parameters import (
    PARAMETERS,
    RESET,
    START,
    NodeConfig,
    build_simulator,
    check_rates,
    ticks_between,
)
from vjm_ros.realtime.wrenches import WrenchBuffer
from vjm_ros.ros import conversions as conv
from vjm_ros.ros.clock_owner import CONFLICT, ClockOwner
from vjm_ros.ros.command_wire import submit_effort_bytes, submit_joint_command_bytes
from vjm_ros.ros.descriptors import descriptor
from vjm_ros.ros.runtime import (
    PolledGroup,
    Spinner,
    StopOnSignals,
    raise_priority,
    raw_publish,
    take_all,
)
from vjm_ros.ros.wire import MarkerWire, TickWire
from vjm_ros.ros.wrench_input import subscribe_external_wrench
from vjm_ros.scene.description import assembled_scene_yaml
from vjm_ros.scene.loader import Scene, load_scene
from vjm_ros.sim.samples import Sample
from vjm_ros.sim.simulator import Simulator

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.parameter import Parameter

NODE_NAME = "vjm_sim_node"
EXIT_OK, EXIT_ERROR, EXIT_CONFIG, EXIT_DIVERGED = 0, 1, 2, 3
SWITCH_INTERVAL = 1e-4
"""The interpreter's thread switch interval in the node, s (Python's default is 5 ms): when the
tick is due while the executor thread runs Python code, the tick thread gets the interpreter
within this time. Measured under a 10 kHz command flood with ``realtime_priority:=50``: 78 % of
the 1 kHz ticks kept with the default, 99.7 % with 0.1 ms."""
WARNING_PERIOD = 1.0
"""Seconds between two warnings of one kind (bad commands, clamping, timeouts)."""
NOTICE_LEVELS = {"command_timeout": "warning", "lockstep_timeout": "warning",
                 "log_failed": "warning", CONFLICT: "warning"}


def open_recorders(
    config: NodeConfig, scene: Scene, sim: Simulator, node_name: str, namespace: str = ""
) -> list:
    """The MCAP and rerun recorders asked for by ``mcap`` and ``rrd``
    (:func:`~vjm_ros.logs.opening.open_recorders`, with the node's settings in the logs).

    Raises
    ------
    ConfigurationError
        A recorder is not available or its file cannot be opened.
    """
    settings = {**sim.describe(), "node": node_name, "namespace": namespace,
                "realtime": config.realtime, "lockstep": config.lockstep}
    return open_log_recorders(scene.model, settings, scene.text, mcap=config.mcap,
                              rrd=config.rrd, duration=config.duration, rate=sim.settings.rate)


COMPILING_NOTE = (
    "the compiled kernels are not in numba's cache yet (a first run on this machine): the ticks "
    "run as plain Python (0.1-1.5 ms each on the thesis scenes, so 1 kHz may not be kept) until "
    "a background process has compiled them (15-40 s); later starts load them")


class SimNode(Node):
    """The simulator node: parameters, publishers, subscriptions and services around a TickLoop.

    Parameters
    ----------
    context : rclpy.context.Context, optional
    parameter_overrides : list of rclpy.parameter.Parameter, optional
        Values for the parameters of :data:`~vjm_ros.realtime.parameters.PARAMETERS`.
    node_name : str
    namespace : str, optional

    Raises
    ------
    VjmError, ValueError, rclpy.exceptions.ParameterException
        A parameter value, the scene or a log file cannot be used (nothing is left open).
    """

    def __init__(self, *, context: Context | None = None,
                 parameter_overrides: list[Parameter] | None = None, node_name: str = NODE_NAME,
                 namespace: str | None = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        for spec in PARAMETERS:
            self.declare_parameter(spec.name, spec.default, descriptor(spec))
        self.config = NodeConfig.from_values(
            {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS}
        )
        positions = self._declare_initial_positions(load_scene(self.config.scene).model)
        self.scene, sim = build_simulator(self.config, positions)
        self._pending_scene: Scene | None = None
        recorders = open_recorders(self.config, self.scene, sim, self.get_name(),
                                   self.get_namespace())
        self._throttle = Throttle(WARNING_PERIOD)
        self._make_publishers()
        self._send_truth = self._open_ground_truth() if sim.sensors is not None else None
        self._clock_owner = ClockOwner(self, self.notice, self.config.publish_clock)
        self._wrench_pubs: dict[str, object] = {}
        self._adopt(sim.model)
        self.loop = TickLoop(sim, self._commands_for(sim), self, self._options(sim),
                             recorders, paused=self.config.start_paused,
                             wrenches=WrenchBuffer(sim.model.points, self.config.command_timeout))
        subscribe_external_wrench(self, lambda: self.loop.wrenches, self._warn)
        self._publish_scene()
        polled = PolledGroup(lambda: self.loop.polls_inputs)
        self._polled = [
            # taken as bytes, read by command_wire (a typed take cost 4x the raw one)
            (self.create_subscription(Float64MultiArray, "~/effort_commands", self._on_efforts,
                                      10, callback_group=polled, raw=True), self._on_efforts),
            (self.create_subscription(JointState, "~/joint_commands", self._on_joint_commands,
                                      10, callback_group=polled, raw=True),
             self._on_joint_commands),
        ]
        self.loop.poll_inputs = self._poll_commands
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.create_service(Trigger, "~/step", self._on_step)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        s = sim.settings
        self.get_logger().info(
            f"scene {self.scene.name}: {s.rate:g} Hz, {s.substeps} substep(s), {s.integrator}, "
            f"{s.closure} closure; {'lockstep' if self.config.lockstep else ('realtime' if self.config.realtime else 'fast')}"
            f"{', paused' if self.config.start_paused else ''}; actuators "
            f"{sim.model.actuator_names} on {self.get_fully_qualified_name()}/effort_commands"
        )
        if sim.mechanism.compiling:
            self.get_logger().warning(COMPILING_NOTE)

    # ------------------------------------------------------------------ set-up
    def _declare_initial_positions(self, model) -> dict[str, float]:
        """Declare ``initial_positions.<joint>`` for every joint; the values given (not NaN).

        A given joint starts at its value (rad or m) and the others are assembled so that the
        closures hold; read-only after start.
        """
        given = {}
        overrides = getattr(self, "_parameter_overrides", None) or {}
        for key in overrides:
            if key.startswith("initial_positions.") and key[18:] not in model.joint_names:
                raise ConfigurationError(
                    f"{key}: expected a joint of {model.name} ({', '.join(model.joint_names)}), "
                    f"found {key[18:]!r}"
                )
        for name in model.joint_names:
            descriptor_ = ParameterDescriptor(
                name=f"initial_positions.{name}",
                description=f"initial value of joint {name} (rad or m); NaN: the scene's",
                read_only=True,
                dynamic_typing=True,
            )
            value = self.declare_parameter(f"initial_positions.{name}", math.nan, descriptor_).value
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ConfigurationError(
                    f"initial_positions.{name}: expected a number, found {value!r}") from None
            if not math.isnan(value):
                given[name] = value
        return given

    def _make_publishers(self) -> None:
        self._joint_pub = self.create_publisher(JointState, "joint_states", 10)
        self._forces_pub = self.create_publisher(Float64MultiArray, "~/constraint_forces", 10)
        self._energy_pub = self.create_publisher(Float64MultiArray, "~/energy", 10)
        self._markers_pub = self.create_publisher(MarkerArray, "~/markers", 10)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        # the last 100 events reach a subscriber that matches late (a transient-local one)
        self._events_pub = self.create_publisher(
            String, "~/events", QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                           durability=DurabilityPolicy.TRANSIENT_LOCAL))
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._scene_pub = self.create_publisher(String, "~/scene_description", latched)
        self._description_pub = self.create_publisher(String, "robot_description", latched)
        # the tick loop's per-tick messages are serialized bytes (TickWire, MarkerWire)
        self._send_joints = raw_publish(self._joint_pub)
        self._send_forces = raw_publish(self._forces_pub)
        self._send_energy = raw_publish(self._energy_pub)
        self._send_markers = raw_publish(self._markers_pub)

    def _commands_for(self, sim: Simulator) -> CommandBuffer:
        model = sim.model
        return CommandBuffer(model.actuator_names, model.joint_names, sim.limits,
                             self.config.command_timeout)

    def _options(self, sim: Simulator) -> LoopOptions:
        c = self.config
        return LoopOptions(
            realtime=c.realtime,
            duration=c.duration,
            publish_every=ticks_between(c.publish_rate_hz, sim.settings.rate),
            forces_every=ticks_between(c.forces_rate_hz, sim.settings.rate),
            publish_clock=c.publish_clock,
            lockstep=c.lockstep,
            lockstep_timeout=c.lockstep_timeout,
            marker_period=1.0 / c.marker_rate_hz if c.marker_rate_hz > 0 else 0.0,
            wait_for_command=c.wait_for_command,
        )

    def _adopt(self, model) -> None:
        """Names, layouts and one wrench publisher per closure and per stop for ``model``."""
        self._joint_names = list(model.joint_names)
        self._force_names = list(model.force_names)
        for name in list(self._wrench_pubs):
            if name not in self._force_names:
                self.destroy_publisher(self._wrench_pubs.pop(name))
        for name in self._force_names:
            if name not in self._wrench_pubs:
                self._wrench_pubs[name] = self.create_publisher(
                    WrenchStamped, conv.wrench_topic(name), 10)
        self._send_wrenches = [raw_publish(self._wrench_pubs[n]) for n in self._force_names]
        self._wire = TickWire(self._joint_names, self._force_names)
        self._marker_wire = MarkerWire()
        self._trace = conv.TipTrace(len(model.chains))

    # ------------------------------------------------------------------ outputs (loop thread)
    def rebuilt(self, simulator: Simulator) -> None:
        """Adopt the simulator built with settings changed since the last reset."""
        if self._pending_scene is not None:
            self.scene, self._pending_scene = self._pending_scene, None
            self._publish_scene()
        self._adopt(simulator.model)
        self.loop.options = self._options(simulator)

    def _publish_scene(self) -> None:
        """``~/scene_description``: the scene YAML with its assembled initial state, and
        ``robot_description``: its URDF, joint positions = joint coordinates (both latched)."""
        self._scene_pub.publish(String(data=assembled_scene_yaml(self.scene)))
        self._description_pub.publish(String(data=scene_urdf(self.scene.model, plant=self.scene.plant)))

    def clock(self, t: float) -> None:
        """Publish ``/clock`` (opening its publisher when ``publish_clock`` was turned on)."""
        send = self._clock_owner.send or self._clock_owner.open()
        send(self._wire.clock_at(t))

    def joints(self, t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
        """Publish ``/joint_states``."""
        self._send_joints(self._wire.joint_state(t, q, qd, effort))

    def ground_truth(self, t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
        """Publish ``~/ground_truth/joint_states``: the exact state, when ``joint_states``
        carries what the scene's sensors measure."""
        if self._send_truth is None:  # a scene with sensors adopted at a reset
            self._send_truth = self._open_ground_truth()
        self._send_truth(self._wire.joint_state(t, q, qd, effort))

    def _open_ground_truth(self):
        return raw_publish(self.create_publisher(JointState, "~/ground_truth/joint_states", 10))

    def dynamics(self, sample: Sample, t: float) -> None:
        """Publish the constraint forces, wrenches (stamped ``t``, s) and energy of a sample."""
        forces = sample.closure_force
        wire = self._wire
        self._send_forces(wire.constraint_forces(forces))
        for i, send in enumerate(self._send_wrenches):
            send(wire.wrench(i, forces[i], t))
        self._send_energy(wire.energy_values(sample.energy))

    def markers(self, sample: Sample, t: float) -> None:
        """Publish ``~/markers`` stamped ``t`` (s); the tip trace gains the sample's tips."""
        self._trace.add(sample)
        self._send_markers(self._marker_wire.markers(sample, t, self._trace.strips()))

    def diagnostics(self, report: dict, paused: bool, level: int | None = None,
                    message: str | None = None) -> None:
        """Publish ``/diagnostics``; drop the ``/clock`` publisher once ``publish_clock`` is
        false (so that the graph shows who owns the clock; this runs in the loop's thread)."""
        if not self.loop.options.publish_clock:
            self._clock_owner.close()
        if level is None:
            level, message = assess(report, paused)
        self._diag_pub.publish(conv.diagnostics(
            report, level, message, report["sim_time"], f"{self.get_name()}: simulation",
            self.scene.name))

    def notice(self, kind: str, text: str) -> None:
        """Log an event (warnings throttled per kind) and publish it on ``~/events``."""
        self._events_pub.publish(String(data=events.line(kind, text)))
        if NOTICE_LEVELS.get(kind) == "warning":
            self._warn(kind, text)
        else:
            self.get_logger().info(text)

    def _warn(self, key: str, text: str) -> None:
        held = self._throttle(key)
        if held is None:
            return
        suffix = f" ({held} more suppressed in the last {WARNING_PERIOD:g} s)" if held else ""
        self.get_logger().warning(text + suffix)

    # ------------------------------------------------------------------ inputs (tick loop or executor thread)
    def _on_efforts(self, data: bytes) -> None:
        """A serialized ``~/effort_commands`` message (``Float64MultiArray``)."""
        self._judge("~/effort_commands", submit_effort_bytes(self.loop.commands, data))

    def _on_joint_commands(self, data: bytes) -> None:
        """A serialized ``~/joint_commands`` message (``JointState``)."""
        self._judge("~/joint_commands", submit_joint_command_bytes(self.loop.commands, data))

    def _poll_commands(self) -> None:
        """Run the command handlers on what arrived since the previous tick (loop thread)."""
        for handler, msg in take_all(self._polled):
            handler(msg)

    def _judge(self, topic: str, verdict: Verdict) -> None:
        if not verdict.accepted:
            self._warn(f"{topic} {verdict.kind}", f"{topic}: command refused: {verdict.reason}")
        for text in verdict.clamped:
            self._warn(f"{topic} clamped", f"{topic}: effort {text}")

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self.loop.pause(request.data)
        response.success = True
        state = "paused" if request.data else "running"
        response.message = f"{state} at t = {self.loop.time:.6g} s"
        return response

    def _on_step(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if not self.loop.paused:
            response.success = False
            response.message = "not paused: ~/step runs one tick only while paused (call ~/pause first)"
            return response
        t = self.loop.step()
        response.success = t is not None
        response.message = f"stepped to t = {t:.6g} s" if t is not None else "the tick loop is not running"
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        done = self.loop.reset()
        response.success = done
        response.message = (
            f"reset to the initial state of {self.scene.name}; simulated time goes on from "
            f"t = {self.loop.time:.6g} s" if done else "the tick loop is not running")
        return response

    def _on_set_parameters(self, params) -> SetParametersResult:
        try:
            new = self.config.updated({p.name: p.value for p in params})
            changed = new.changed(self.config)
            if START in changed.values():
                frozen = [k for k, v in changed.items() if v == START]
                raise ConfigurationError(f"{', '.join(frozen)}: read-only after start")
            pending = None
            if RESET in changed.values():
                if new.scene != self.config.scene and self.loop.recorders:
                    raise ConfigurationError("scene: cannot change while recording (mcap/rrd)")
                pending = build_simulator(new)
            check_rates(new, self.loop.sim.settings.rate)
        except (VjmError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.config = new
        if pending is not None:
            self._pending_scene, sim = pending
            self.loop.replace_on_reset(sim, self._commands_for(sim))
            self.get_logger().info(
                f"{', '.join(k for k, v in changed.items() if v == RESET)}: "
                "takes effect at the next ~/reset")
        self.loop.commands.timeout = new.command_timeout
        self.loop.options = self._options(self.loop.sim)
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ end
    def close(self) -> None:
        """Finalize the recorders (idempotent), after the ticks still on their way to them."""
        try:
            self.loop.log_rows.close()
        except Exception as exc:  # the rows are lost, the logs are still finalized
            self.get_logger().error(f"writing the last ticks to the logs: {exc}")
        for rec in list(self.loop.recorders):
            try:
                rec.close()
            except Exception as exc:  # a log that cannot be finalized must not hide the rest
                self.get_logger().error(f"closing {type(rec).__name__}: {exc}")
            self.loop.logs.active.remove(rec)

    def summary(self, reason: str, wall: float, cpu: float) -> dict:
        """Figures of the whole run (logged on exit); ``wall`` and ``cpu`` (process time) in s.

        ``sim_time`` is the simulated time published last (``/clock``: since the start, across
        resets), ``ticks`` the ticks run since the start and ``realtime_factor`` their ratio to
        ``wall``. ``ticking_wall_time`` and ``ticking_cpu_time`` (s) count from the first tick
        on (after a ``wait_for_command`` hold), the figures a per-tick cost is taken from.
        """
        loop = self.loop
        stats = loop.pacer.stats
        since = loop.ticking_since
        ticking = ((time.perf_counter() - since[0], time.process_time() - since[1])
                   if since is not None else (0.0, 0.0))
        return {
            "scene": self.scene.name,
            "reason": reason,
            "sim_time": loop.time,
            "ticks": loop.ticks,
            "wall_time": wall,
            "cpu_time": cpu,
            "ticking_wall_time": ticking[0],
            "ticking_cpu_time": ticking[1],
            "realtime_factor": loop.time / wall if wall > 0 else None,
            "realtime": loop.options.realtime,
            "lockstep": loop.options.lockstep,
            "late_ticks": stats.late,
            "missed_ticks": stats.missed,
            "resyncs": stats.resyncs,
            "max_lateness": stats.max_lateness,
            "lockstep_timeouts": loop.lockstep_timeouts,
            "commands_accepted": loop.commands.accepted,
            "commands_rejected": loop.commands.rejected,
            "refused_oversize_commands": loop.commands.oversize,
            "command_timeouts": loop.commands.timeouts,
            "max_closure_error": loop.monitor.max_closure_error,
        }

    def fail(self, exc: DivergenceError) -> None:
        """Report a divergence on the log, ``~/events`` and ``/diagnostics``."""
        self.get_logger().error(str(exc))
        self._events_pub.publish(String(data=f"diverged: {exc}"))
        report = self.loop.report()
        self.diagnostics(report, False, ERROR, str(exc))


def run(node: SimNode) -> int:
    """Spin ``node`` in a background thread and run its tick loop in this thread.

    The executor thread starts first, so only the tick loop gets ``realtime_priority``; the
    callbacks are gated out of realtime ticks (:class:`~.gate.Gate`).

    Returns
    -------
    int
        :data:`EXIT_OK` (duration reached or stopped) or :data:`EXIT_DIVERGED`.
    """
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    sys.setswitchinterval(SWITCH_INTERVAL)
    spinner = Spinner(executor, node.loop.gate).start()
    raise_priority(node.config.realtime_priority, node.get_logger())
    wall0, cpu0 = time.perf_counter(), time.process_time()
    try:
        reason = node.loop.run()
        summary = node.summary(reason, time.perf_counter() - wall0, time.process_time() - cpu0)
        node.get_logger().info(
            f"stopped ({reason}) at t = {summary['sim_time']:.6g} s after {summary['ticks']} ticks; "
            f"summary {json.dumps(summary)}")
        return EXIT_OK
    except DivergenceError as exc:
        node.fail(exc)
        return EXIT_DIVERGED
    finally:
        spinner.stop()
        executor.remove_node(node)
        executor.shutdown()


def main(args: list[str] | None = None) -> int:
    """Console entry point ``vjm_sim_node`` (see the module documentation for exit codes)."""
    with StopOnSignals() as stop:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except Exception as exc:
            print(f"{NODE_NAME}: cannot start ROS 2: {exc}", file=sys.stderr)
            return EXIT_CONFIG
        node = None
        try:
            try:
                node = SimNode()
            except (VjmError, ValueError, rclpy.exceptions.ParameterException) as exc:
                rclpy.logging.get_logger(NODE_NAME).error(f"cannot start: {exc}")
                return EXIT_CONFIG
            stop.attach(node.loop)
            return run(node)
        except Exception:
            traceback.print_exc()
            return EXIT_ERROR
        finally:
            if node is not None:
                node.close()
                node.destroy_node()
            rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
