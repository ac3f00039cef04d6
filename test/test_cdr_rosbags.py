"""The logs' CDR bytes are what rosbags' schema-driven serializer writes.

rosbags (a third-party ROS bag library) builds its serializer from the ROS 2 Kilted message
definitions, the same ones the logs' schemas come from (:mod:`vjm_ros.logs.msgdefs`). Here the
rosbags message objects are built by this test's own code from the message dicts, serialized by
rosbags, and compared byte for byte with :func:`vjm_ros.logs.cdr.encode` and with the per-tick
fast paths, on messages of a real run; the schema texts name exactly the fields rosbags knows.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import four_bar_samples
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Nodetype

from vjm_ros.logs import cdr, messages, msgdefs

TYPESTORE = get_typestore(Stores.ROS2_KILTED)
_NUMPY = {"float64": np.float64, "float32": np.float32, "int32": np.int32, "uint32": np.uint32,
          "uint8": np.uint8, "int8": np.int8, "int64": np.int64, "uint64": np.uint64}


def build(type_name: str, value: dict):
    """The rosbags message of ``type_name`` holding the fields of a message dict."""
    _, fields = TYPESTORE.fielddefs[type_name]
    kwargs = {name: _field(desc, value[name]) for name, desc in fields}
    return TYPESTORE.types[type_name](**kwargs)


def _field(desc, value):
    kind, detail = desc
    if kind == Nodetype.NAME:
        return build(detail, value)
    if kind == Nodetype.BASE:
        return value
    (sub_kind, sub_detail), _ = detail  # a sequence or an array
    if sub_kind == Nodetype.BASE and sub_detail[0] in _NUMPY:
        return np.asarray(value, dtype=_NUMPY[sub_detail[0]])
    return [_field((sub_kind, sub_detail), v) for v in value]


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


def test_encode_matches_rosbags_byte_for_byte(sample_messages):
    for type_name, value in sample_messages:
        ours = cdr.encode(type_name, value)
        theirs = bytes(TYPESTORE.serialize_cdr(build(type_name, value), type_name))
        assert ours == theirs, type_name


@pytest.mark.parametrize("ticks", [1, 10])
def test_fast_paths_match_rosbags_byte_for_byte(ticks):
    """Fixed-layout encoders against rosbags on states of a run, stamps from 0 to beyond 2**32 ns."""
    scene, _, samples = four_bar_samples(ticks)
    model = scene.model
    joints = cdr.joint_state_encoder(model.joint_names)
    layout = messages.labelled_layout(model.closure_names, 3)
    forces = cdr.multi_array_encoder(layout, 3 * len(model.closures))
    wrench = cdr.wrench_stamped_encoder()

    def rosbags(type_name, value):
        return bytes(TYPESTORE.serialize_cdr(build(type_name, value), type_name))

    for s, ns in zip(samples, (0, 999_999_999, 4_294_967_297_123, 7 * 10**15), strict=False):
        assert joints(ns, s.q, s.qd, s.effort) == rosbags(
            messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns))
        assert forces(s.closure_force.reshape(-1)) == rosbags(
            messages.FLOAT64_MULTI_ARRAY, messages.constraint_forces(model.closure_names, s))
        fx, fy, mz = s.closure_force[0]
        assert wrench(ns, fx, fy, mz) == rosbags(messages.WRENCH_STAMPED, messages.wrench(s, 0, ns))
        assert cdr.encode_clock(ns) == rosbags(messages.CLOCK, messages.clock(ns))
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
