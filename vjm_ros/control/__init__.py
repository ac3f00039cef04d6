"""The closed-chain model for controllers (no ROS): :class:`ClosedChainModel`."""

from vjm_ros.control.closed_model import (
    ClosedChainModel,
    InfeasibleEffortsError,
    ReducedDynamics,
    SingularConfigurationError,
    distribute,
)

__all__ = [
    "ClosedChainModel",
    "InfeasibleEffortsError",
    "ReducedDynamics",
    "SingularConfigurationError",
    "distribute",
]
