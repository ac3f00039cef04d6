"""The closed-chain model for controllers (no ROS): :class:`ClosedChainModel`."""

from vjm_ros.control.closed_model import (
    ArgumentTypeError,
    ClosedChainModel,
    InfeasibleEffortsError,
    ReducedDynamics,
    SingularConfigurationError,
    distribute,
    null_direction,
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
