"""The logs' CDR bytes are what rosbags' schema-driven serializer writes.

rosbags (a third-party ROS bag library) builds its serializer from the ROS 2 Kilted message
definitions, the same ones the logs' schemas come from (:mod:`vjm_ros.logs.msgdefs`). Here the
rosbags message objects are built by the tests' own code from the message dicts
(``test/rosbags_cdr.py``), serialized by rosbags, and compared byte for byte with the package's
one encoder of each type, on messages of a real run; the schema texts name exactly the fields
rosbags knows.
"""

from __future__ import annotations

import pytest
from conftest import four_bar_samples
from rosbags_cdr import TYPESTORE, serialize

from vjm_ros.logs import cdr, messages, msgdefs


@pytest.fixture(scope="module")
def sample_messages():
    scene, _, samples = four_bar_samples(10)
    model, s, ns = scene.model, samples[7], 3_000_000_001
    return [
        (messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns)),
        (messages.FLOAT64_MULTI_ARRAY, messages.constraint_forces(model.closure_names, s)),
        (messages.FLOAT64_MULTI_ARRAY, messages.energy(s)),
        (messages.WRENCH_STAMPED, messages.wrench(s, 0, ns)),
        (messages.CLOCK, messages.clock(ns)),
        (messages.STRING, messages.event("reset at t = 0.007 s")),
        (messages.MARKER_ARRAY, messages.markers(s, ns)),
    ]


def test_every_logged_type_is_covered(sample_messages):
    assert {t for t, _ in sample_messages} == set(msgdefs.LOGGED_TYPES)


def _encoded(type_name: str, value: dict) -> bytes:
    """A message dict through the package's one encoder of its type."""
    stamp = value.get("header", {}).get("stamp")
    ns = stamp["sec"] * 10**9 + stamp["nanosec"] if stamp else None
    if type_name == messages.JOINT_STATE:
        return cdr.joint_state_layout(value["name"]).encode(
            ns, value["position"], value["velocity"], value["effort"])
    if type_name == messages.FLOAT64_MULTI_ARRAY:
        return cdr.multi_array_layout(value["layout"], len(value["data"])).encode(
            0, *([value["data"]] if value["data"] else []))
    if type_name == messages.WRENCH_STAMPED:
        w = value["wrench"]
        return cdr.wrench_stamped_layout().encode(ns, [w["force"]["x"], w["force"]["y"]],
                                                  [w["torque"]["z"]])
    if type_name == messages.CLOCK:
        return cdr.CLOCK_LAYOUT.encode(value["clock"]["sec"] * 10**9 + value["clock"]["nanosec"])
    if type_name == messages.STRING:
        return cdr.encode_string(value["data"])
    return cdr.encode_markers(value)


def test_every_encoder_matches_rosbags_byte_for_byte(sample_messages):
    for type_name, value in sample_messages:
        assert _encoded(type_name, value) == serialize(type_name, value), type_name
    for text in ("", "a", "abc", "abcd", "ü ∑ reset"):  # every length modulo 4, and UTF-8
        assert cdr.encode_string(text) == serialize(messages.STRING, messages.event(text)), text


@pytest.mark.parametrize("ticks", [1, 10])
def test_fast_paths_match_rosbags_byte_for_byte(ticks):
    """Fixed-layout encoders against rosbags on states of a run, stamps from 0 to beyond 2**32 ns."""
    scene, _, samples = four_bar_samples(ticks)
    model = scene.model
    joints = cdr.joint_state_layout(model.joint_names).encode
    layout = messages.labelled_layout(model.closure_names, 3)
    forces = cdr.multi_array_layout(layout, 3 * len(model.closures)).encode
    wrench = cdr.wrench_stamped_layout().encode

    rosbags = serialize

    for s, ns in zip(samples, (0, 999_999_999, 4_294_967_297_123, 7 * 10**15), strict=False):
        assert joints(ns, s.q, s.qd, s.effort) == rosbags(
            messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns))
        assert forces(0, s.closure_force) == rosbags(
            messages.FLOAT64_MULTI_ARRAY, messages.constraint_forces(model.closure_names, s))
        f = s.closure_force[0]
        assert wrench(ns, f[:2], f[2:]) == rosbags(messages.WRENCH_STAMPED,
                                                   messages.wrench(s, 0, ns))
        assert cdr.CLOCK_LAYOUT.encode(ns) == rosbags(messages.CLOCK, messages.clock(ns))
        markers = messages.markers(s, ns)
        assert cdr.encode_markers(markers) == rosbags(messages.MARKER_ARRAY, markers)


def test_schema_texts_name_the_fields_rosbags_knows():
    for type_name in msgdefs.known_types():
        own = msgdefs.definition(type_name).split("=" * 80)[0]
        names = [ln.split()[1] for ln in own.strip().split("\n") if ln and "=" not in ln]
        assert names == [n for n, _ in TYPESTORE.fielddefs[type_name][1]], type_name
        assert msgdefs.type_hash(type_name).startswith("RIHS01_")


def test_the_stored_definitions_and_hashes_are_rosbags_typestore_s():
    """``ros2_types.json`` (read when a log opens) is what rosbags' Kilted typestore gives."""
    assert msgdefs._types() == msgdefs.from_typestore()
