"""rosbags' schema-driven CDR serializer on the logs' message dicts: the third-party reference
the package's encoders (:mod:`vjm_ros.logs.cdr`) are compared with byte for byte.

rosbags (a third-party ROS bag library) builds its serializer from the ROS 2 Kilted message
definitions, the ones the logs' schemas come from (:mod:`vjm_ros.logs.msgdefs`); the rosbags
message objects are built here from the dicts of :mod:`vjm_ros.logs.messages`.
"""

from __future__ import annotations

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Nodetype

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


def serialize(type_name: str, value: dict) -> bytes:
    """CDR bytes (encapsulation header and payload) of a message dict, by rosbags."""
    return bytes(TYPESTORE.serialize_cdr(build(type_name, value), type_name))
