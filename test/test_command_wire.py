"""The node's command decoder (ros/command_wire.py) against rclpy's own serialization.

Oracle: messages built with rclpy's classes and serialized by rclpy (``serialize_message``);
the decoder must give back the same values, for every length, label and name that shifts the
alignment of what follows. Truncated or foreign bytes raise an error naming the field.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from vjm_ros.ros.command_wire import MalformedCommand, joint_state_efforts, multi_array_values

RNG = np.random.default_rng(11)


def _label(k: int) -> str:
    return "é" * (k % 3) + "x" * k  # multi-byte characters and every length modulo 8


@pytest.mark.parametrize("dims", [0, 1, 2, 3])
@pytest.mark.parametrize("count", [0, 1, 2, 3, 7])
def test_multi_array_values_equal_rclpys(dims, count):
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=_label(d + count), size=d, stride=3 * d)
                      for d in range(dims)]
    msg.layout.data_offset = dims + count
    values = RNG.normal(size=count) * 10.0 ** RNG.integers(-300, 300, size=count)
    msg.data = values.tolist()
    got = multi_array_values(serialize_message(msg))
    assert got.dtype == np.float64 and got.flags.writeable
    np.testing.assert_array_equal(got, values)  # bit for bit: the bytes are copied


def test_multi_array_values_keep_non_finite_values_for_the_buffer_to_refuse():
    msg = Float64MultiArray(data=[math.nan, math.inf, -0.0])
    got = multi_array_values(serialize_message(msg))
    assert math.isnan(got[0]) and got[1] == math.inf and math.copysign(1.0, got[2]) == -1.0


@pytest.mark.parametrize("frame", ["", "w", "world", "a longer frame id"])
@pytest.mark.parametrize("n", [0, 1, 2, 5])
def test_joint_state_names_and_efforts_equal_rclpys(frame, n):
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    msg.header.frame_id = frame
    msg.name = [_label(i + n) + f"j{i}" for i in range(n)]
    msg.position = RNG.normal(size=n % 3).tolist()  # lengths that differ from the names'
    msg.velocity = RNG.normal(size=(n + 1) % 4).tolist()
    efforts = RNG.normal(size=n)
    msg.effort = efforts.tolist()
    names, got = joint_state_efforts(serialize_message(msg))
    assert names == list(msg.name)
    np.testing.assert_array_equal(got, efforts)


def test_big_endian_bytes_read_the_same():
    # the same message written big-endian (encapsulation 00 00): every number byte-swapped
    little = serialize_message(Float64MultiArray(data=[1.5, -2.25]))
    # header | dim count | data_offset | data count | padding to 8 | two doubles
    assert len(little) == 36
    fields = [little[4:8], little[8:12], little[12:16], little[16:20], little[20:28],
              little[28:36]]
    big = b"\x00\x00\x00\x00" + b"".join(f[::-1] for f in fields)
    np.testing.assert_array_equal(multi_array_values(big), [1.5, -2.25])


@pytest.mark.parametrize("cut", [0, 3, 8, 11, 13, 27])
def test_truncated_bytes_name_the_field_and_offset(cut):
    data = serialize_message(Float64MultiArray(data=[1.0, 2.0]))[:cut]
    with pytest.raises(MalformedCommand) as err:
        multi_array_values(data)
    text = str(err.value)
    assert "std_msgs/Float64MultiArray" in text and "byte" in text


def test_joint_state_bytes_with_a_bad_name_are_refused():
    data = bytearray(serialize_message(JointState(name=["a1"], effort=[1.0])))
    at = data.index(b"a1\x00")
    data[at + 2] = ord("x")  # the name's terminating NUL overwritten
    with pytest.raises(MalformedCommand, match="name at byte"):
        joint_state_efforts(bytes(data))
    data[at + 2] = 0
    data[at] = 0xFF  # not UTF-8
    with pytest.raises(MalformedCommand, match="UTF-8"):
        joint_state_efforts(bytes(data))


def test_foreign_encapsulations_are_refused():
    with pytest.raises(MalformedCommand, match="encapsulation"):
        multi_array_values(b"\x00\x07\x00\x00" + bytes(12))  # an XCDR2 identifier
