"""The node's parameters as ROS 2 parameter descriptors (types, ranges, when they apply), from
their ROS-free specification in :mod:`vjm_ros.realtime.parameters`."""

from __future__ import annotations

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)

from vjm_ros.realtime.parameters import RESET, START, ParamSpec


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """ROS parameter descriptor of a :class:`~vjm_ros.realtime.parameters.ParamSpec`.

    Floating-point parameters also accept integers (``-p rate_hz:=500``).
    """
    when = {
        "now": "takes effect at the next tick",
        RESET: "takes effect at the next ~/reset",
        START: "read-only after start",
    }[spec.applies]
    d = ParameterDescriptor(
        name=spec.name,
        description=spec.description,
        read_only=spec.applies == START,
        additional_constraints=when,
    )
    if isinstance(spec.default, bool):
        d.type = ParameterType.PARAMETER_BOOL
    elif isinstance(spec.default, int):
        d.type = ParameterType.PARAMETER_INTEGER
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    elif isinstance(spec.default, float):
        # Dynamic typing lets `-p duration:=5` (an integer) through; NodeConfig checks the type.
        d.dynamic_typing = True
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
        ]
    else:
        d.type = ParameterType.PARAMETER_STRING
        if spec.choices:
            shown = ", ".join(repr(c) for c in spec.choices)
            d.additional_constraints = f"one of {shown}; {when}"
    return d
