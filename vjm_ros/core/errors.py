"""Exceptions raised by vjm_ros.

One base class, :class:`VjmError`; each subclass builds its message from the fields that
locate the fault, so that every error a user meets names what to fix.
"""

from __future__ import annotations


class VjmError(Exception):
    """Base class of every error raised on purpose by vjm_ros."""


class SceneError(VjmError, ValueError):
    """A scene file or scene dictionary is invalid.

    Parameters
    ----------
    source : str
        File name (or ``"<dict>"``) the scene came from.
    key : str
        Key path inside the document, e.g. ``chains[0].links[1].mass``.
    expected : str
        What the key should hold.
    found : object, optional
        What it holds; omitted from the message when not applicable.
    """

    def __init__(self, source: str, key: str, expected: str, found: object = ...):
        self.source = source
        self.key = key
        self.expected = expected
        self.found = found
        where = f"{source}: {key}" if key else source
        msg = f"{where}: expected {expected}"
        if found is not ...:
            shown = repr(found)
            if len(shown) > 200:
                shown = shown[:197] + "..."
            msg += f", found {shown}"
        super().__init__(msg)


class ConfigurationError(VjmError, ValueError):
    """A run setting (integrator, rate, gains, ...) cannot be used."""


class StiffnessError(ConfigurationError):
    """Penalty stiffness beyond what the chosen integrator and step can carry."""


class DivergenceError(VjmError, RuntimeError):
    """The simulation left the range where its results mean anything.

    Parameters
    ----------
    time : float
        Simulated time of the failure, s.
    what : str
        What was found (non-finite state, closure residual beyond its limit, ...).
    closure : str or None
        Name of the closure concerned, if any.
    cause : str
        The likely cause and what to try.
    """

    def __init__(self, time: float, what: str, closure: str | None, cause: str):
        self.time = time
        self.what = what
        self.closure = closure
        self.cause = cause
        at = f" at closure '{closure}'" if closure else ""
        super().__init__(f"simulation diverged at t = {time:.6g} s{at}: {what}. Likely cause: {cause}")
