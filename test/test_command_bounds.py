"""Commands bigger than the scene can need are refused before they are read.

Oracle: messages built with rclpy's classes and serialized by rclpy (``serialize_message``). A
message beyond a bound must be refused from the count at the head of the field alone: the same
refusal comes from its bytes cut right after that count, where reading even one element would
fail as truncated. Messages within the bounds, up to each bound, decode to what rclpy wrote,
as without bounds. The last test runs the oversize study against a live node (its own ROS
domain, every process reaped).
"""

from __future__ import annotations

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray, MultiArrayDimension  # noqa: E402

from vjm_ros.realtime.commands import (  # noqa: E402
    MAX_LAYOUT_DIMS,
    MAX_TEXT_BYTES,
    OVERSIZE,
    SIZE_SLACK,
    CommandBuffer,
    SizeBounds,
)
from vjm_ros.ros.command_wire import (  # noqa: E402
    MalformedCommand,
    OversizeCommand,
    joint_state_efforts,
    multi_array_values,
    submit_effort_bytes,
    submit_joint_command_bytes,
)
from vjm_ros.scene.loader import load_scene  # noqa: E402

MODEL = load_scene("five_bar").model
BOUNDS = SizeBounds.for_scene(MODEL.actuator_names, MODEL.joint_names)
RNG = np.random.default_rng(5)


def buffer() -> CommandBuffer:
    return CommandBuffer(MODEL.actuator_names, MODEL.joint_names,
                         [a.limit for a in MODEL.actuators], 0.0)


def test_bounds_follow_the_scene():
    n = len(MODEL.joint_names)  # 4 joints, 2 actuators
    assert BOUNDS == SizeBounds(values=n + SIZE_SLACK, names=n + SIZE_SLACK,
                                name_bytes=MAX_TEXT_BYTES, dims=MAX_LAYOUT_DIMS,
                                label_bytes=MAX_TEXT_BYTES)
    long = "j" * 300
    assert SizeBounds.for_scene([long], [long, "b"]).name_bytes == 300
    assert buffer().size_bounds == BOUNDS


def wide_layout(dims: int) -> Float64MultiArray:
    """A valid effort command whose layout holds ``dims`` empty dimensions."""
    msg = Float64MultiArray(data=[1.0, -2.0])
    msg.layout.dim = [MultiArrayDimension() for _ in range(dims)]
    return msg


def labelled(label: str) -> Float64MultiArray:
    """A valid effort command whose layout holds one dimension labelled ``label``."""
    msg = Float64MultiArray(data=[1.0, -2.0])
    msg.layout.dim = [MultiArrayDimension(label=label)]
    return msg


def refusal(decode, data: bytes) -> str:
    with pytest.raises(OversizeCommand) as err:
        decode(data, BOUNDS)
    return str(err.value)


def test_a_3_mb_layout_is_refused_from_its_count_alone():
    data = serialize_message(wide_layout(200_000))  # the 3.2 MB command of the defect report
    assert len(data) > 3_200_000
    # without bounds it is a valid command, read element by element
    np.testing.assert_array_equal(multi_array_values(data), [1.0, -2.0])
    reason = refusal(multi_array_values, data)
    assert reason == ("std_msgs/Float64MultiArray: layout.dim holds 200000 dimensions, more than "
                      f"the {MAX_LAYOUT_DIMS} a command to this scene can need (refused unread)")
    # the bytes up to the count (header and the uint32 after it) give the same refusal: nothing
    # after the count was read (an element read there would be truncated)
    assert refusal(multi_array_values, data[:8]) == reason
    with pytest.raises(MalformedCommand, match="layout.dim.label needs 4 bytes"):
        multi_array_values(data[:8])  # what reading the first element does


def cut_after_count(data: bytes, count: int) -> bytes:
    """``data`` up to and including the first aligned little-endian uint32 equal to ``count``
    (the head of the field under test)."""
    word = count.to_bytes(4, "little")
    at = next(i for i in range(4, len(data) - 3, 4) if data[i:i + 4] == word)
    return data[:at + 4]


@pytest.mark.parametrize(
    "field, make, words",
    [
        ("layout.dim", lambda: wide_layout(MAX_LAYOUT_DIMS + 1), "dimensions"),
        ("layout.dim.label", lambda: labelled("x" * (MAX_TEXT_BYTES + 1)),
         f"holds {MAX_TEXT_BYTES + 1} bytes"),
        ("data", lambda: Float64MultiArray(data=np.zeros(BOUNDS.values + 1).tolist()), "values"),
    ],
)
def test_effort_command_fields_beyond_their_bounds_are_refused_unread(field, make, words):
    data = serialize_message(make())
    reason = refusal(multi_array_values, data)
    assert reason.startswith(f"std_msgs/Float64MultiArray: {field} holds ") and words in reason
    head = {"layout.dim": MAX_LAYOUT_DIMS + 1, "layout.dim.label": MAX_TEXT_BYTES + 2,
            "data": BOUNDS.values + 1}[field]
    assert refusal(multi_array_values, cut_after_count(data, head)) == reason


@pytest.mark.parametrize(
    "field, make, head",
    [
        ("name", lambda: JointState(name=[f"j{i}" for i in range(BOUNDS.names + 1)]),
         BOUNDS.names + 1),
        ("name", lambda: JointState(name=["n" * (BOUNDS.name_bytes + 1)], effort=[1.0]),
         BOUNDS.name_bytes + 2),
        ("effort", lambda: JointState(name=["left_base"],
                                      effort=np.ones(BOUNDS.values + 1).tolist()),
         BOUNDS.values + 1),
    ],
)
def test_joint_command_fields_beyond_their_bounds_are_refused_unread(field, make, head):
    msg = make()
    msg.header.frame_id = "world"
    data = serialize_message(msg)
    reason = refusal(joint_state_efforts, data)
    assert reason.startswith(f"sensor_msgs/JointState: {field} holds "), reason
    assert refusal(joint_state_efforts, cut_after_count(data, head)) == reason


def test_commands_up_to_the_bounds_decode_as_without_them():
    for dims in (0, 1, MAX_LAYOUT_DIMS):
        for count in (0, 2, BOUNDS.values):
            msg = Float64MultiArray()
            # labels of MAX_TEXT_BYTES UTF-8 bytes and a little less, some with 2-byte letters
            labels = ["é" * (k % 3) + "x" * (MAX_TEXT_BYTES - 2 * (k % 3) - k % 5)
                      for k in range(dims)]
            assert all(len(t.encode()) <= MAX_TEXT_BYTES for t in labels)
            msg.layout.dim = [MultiArrayDimension(label=t, size=k, stride=2 * k)
                              for k, t in enumerate(labels)]
            msg.layout.data_offset = dims
            msg.data = RNG.normal(size=count).tolist()
            data = serialize_message(msg)
            got = multi_array_values(data, BOUNDS)
            np.testing.assert_array_equal(got, multi_array_values(data))
            np.testing.assert_array_equal(got, deserialize_message(data, Float64MultiArray).data)
    for n in (1, 2, BOUNDS.names):
        names = [("ü" * 3 + f"j{i}").ljust(BOUNDS.name_bytes - 3, "z") if i % 2 else f"j{i}"
                 for i in range(n)]
        msg = JointState(name=names, position=RNG.normal(size=200).tolist(),  # not bounded:
                         velocity=RNG.normal(size=3).tolist(),  # skipped without reading
                         effort=RNG.normal(size=n).tolist())
        data = serialize_message(msg)
        assert all(len(s.encode()) <= BOUNDS.name_bytes for s in names)
        got_names, got = joint_state_efforts(data, BOUNDS)
        assert got_names == names and got_names == joint_state_efforts(data)[0]
        np.testing.assert_array_equal(got, msg.effort)


def test_the_buffer_counts_what_it_refused_for_its_size():
    commands = buffer()
    verdict = submit_effort_bytes(commands, serialize_message(wide_layout(1000)))
    assert not verdict.accepted and verdict.kind == OVERSIZE
    assert "layout.dim holds 1000 dimensions" in verdict.reason
    verdict = submit_joint_command_bytes(
        commands, serialize_message(JointState(name=["x"] * 5000, effort=[0.0] * 5000)))
    assert not verdict.accepted and verdict.kind == OVERSIZE
    assert (commands.oversize, commands.rejected, commands.accepted) == (2, 2, 0)
    # within the bounds: judged as before (here a wrong length, then a valid command)
    verdict = submit_effort_bytes(commands, serialize_message(Float64MultiArray(data=[1.0] * 3)))
    assert not verdict.accepted and verdict.kind != OVERSIZE
    assert submit_effort_bytes(commands, serialize_message(wide_layout(1))).accepted
    assert (commands.oversize, commands.rejected, commands.accepted) == (2, 3, 1)
    assert commands.efforts.tolist() == [1.0, -2.0]


@pytest.mark.parametrize("dims", [0, 1, 3, 1000])
@pytest.mark.parametrize("values", [[], [1.5], [0.0, -2.0]])
@pytest.mark.parametrize("label", ["", "ab", "abcd"])
def test_the_oversize_studys_command_is_what_rclpy_writes_and_reads(dims, values, label):
    """``benchmarks/oversize.py`` builds its 3.2 MB command without 200 000 Python objects: the
    bytes are as long as rclpy's for the same message, and rclpy reads them back as it."""
    from benchmarks.oversize import wide_layout_command

    msg = Float64MultiArray(data=values)
    msg.layout.dim = [MultiArrayDimension(label=label) for _ in range(dims)]
    data = wide_layout_command(dims, values, label)
    assert len(data) == len(serialize_message(msg))
    assert deserialize_message(data, Float64MultiArray) == msg


@pytest.mark.ros
@pytest.mark.slow  # a live node under the benchmark's stream (about 10 s)
def test_the_oversize_study_runs_a_node_that_refuses_the_stream():
    """``python -m benchmarks.oversize`` end to end, one second per run: its figures are
    benchmarks (printed, not asserted); what is asserted is that the stream reached the node
    and that the node refused it for its size, and nothing else."""
    from benchmarks import oversize

    row = oversize.measure("five_bar", seconds=1.0)
    print(oversize._format(row))
    alone, stream = row["alone"], row["stream"]
    assert alone["ticks"] > 0 and stream["ticks"] > 0
    assert alone["refused_oversize_commands"] == 0 == alone["commands_rejected"]
    assert stream["stream_sent"] >= 1 and stream["stream_bytes"] > 3_200_000
    assert 1 <= stream["refused_oversize_commands"] <= stream["stream_sent"]
    assert stream["commands_rejected"] == stream["refused_oversize_commands"]
