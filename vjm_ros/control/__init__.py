"""The closed-chain model for controllers (no ROS): :class:`ClosedChainModel`."""

from vjm_ros.control.closed_model import ClosedChainModel, ReducedDynamics
from vjm_ros.control.distribution import distribute, null_direction
from vjm_ros.control.errors import (
    ArgumentTypeError,
    InfeasibleEffortsError,
    SingularConfigurationError,
)

__all__ = [
    "ArgumentTypeError",
    "ClosedChainModel",
    "InfeasibleEffortsError",
    "ReducedDynamics",
    "SingularConfigurationError",
    "distribute",
    "null_direction",
]
