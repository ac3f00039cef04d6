"""Errors of the closed-chain model for controllers.

Each names the argument or the actuator concerned, what was expected and what was found. They
derive from :class:`~vjm_ros.core.errors.VjmError` (the ``vjm`` command turns
:class:`~vjm_ros.core.errors.ConfigurationError` into exit code 2, any other one into 1).
"""

from __future__ import annotations

from vjm_ros.core.errors import ConfigurationError, VjmError


class ArgumentTypeError(ConfigurationError, TypeError):
    """An argument is not of the kind expected (text where numbers are expected, ...)."""


class SingularConfigurationError(VjmError, ValueError):
    """The asked quantity is not determined at this pose.

    Either the dependent coordinates are not determined by the independent ones (``A_v`` loses
    rank), or a point's acceleration cannot be chosen freely (its task Jacobian loses rank).
    """


class InfeasibleEffortsError(VjmError):
    """No distribution of efforts within the actuators' limits gives the asked motion.

    Attributes
    ----------
    actuator : str or None
        The actuator's joint whose effort is furthest beyond its limit (None when the
        actuators cannot produce the motion at all).
    needed, limit : float or None
        Its effort and limit, N m or N.
    """

    def __init__(self, message: str, actuator: str | None = None,
                 needed: float | None = None, limit: float | None = None) -> None:
        super().__init__(message)
        self.actuator = actuator
        self.needed = needed
        self.limit = limit
