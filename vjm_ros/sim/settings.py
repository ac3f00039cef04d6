"""Run settings: what they are, and the one place where they are resolved.

:func:`resolve_settings` is how ``vjm run``, the node and the studies turn what a user gave (flags,
ROS parameters, sweep axes) plus the scene's defaults into :class:`SimulationSettings`, with the
same rules everywhere: a given value wins over the scene's, a stiffness given without damping
means no damping, a natural frequency without a damping ratio means critical damping, and raw
and modal gains cannot be mixed.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from vjm_ros.core.compiled import KERNELS
from vjm_ros.core.errors import ConfigurationError
from vjm_ros.core.integrators import make_integrator


@dataclass(frozen=True)
class SimulationSettings:
    """How to integrate a scene.

    Attributes
    ----------
    integrator : str
        Registry name (see :data:`vjm_ros.core.integrators.INTEGRATORS`).
    closure : str
        ``"penalty"`` or ``"exact"``.
    rate : float
        Control ticks per second, Hz.
    substeps : int
        Fixed steps per tick.
    kp, kv : float or None
        Raw penalty gains (N/m, N s/m; N m/rad for angle rows). Used when given.
    omega_n, zeta : float or None
        Penalty gains as natural frequency (rad/s) and damping ratio per row, through the
        effective mass at the initial pose. Used when ``kp`` is not given.
    alpha, beta : float
        Baumgarte gains of the exact closure, 1/s.
    projection : bool
        Exact closure only: project ``q``, ``qd`` onto the closure manifold after each tick.
    rtol, atol : float
        Tolerances of adaptive integrators.
    kernel : str
        ``"auto"`` (the compiled kernels: machine code with numba, plain Python without it) or
        ``"numba"`` (the same, an error without numba). The former ``"numpy"`` formulation is
        refused with a message naming these two.
    check_stiffness : bool
        Refuse penalty gains beyond the integrator's stability bound before running (judged on
        the coupled closure modes at the initial pose, see :attr:`Simulator.stiffness_report`).
    divergence_limit : float or None
        Largest closure residual (m or rad) before the run is stopped; None disables the check.
    """

    integrator: str = "rk4"
    closure: str = "penalty"
    rate: float = 1000.0
    substeps: int = 1
    kp: float | None = None
    kv: float | None = None
    omega_n: float | None = None
    zeta: float | None = None
    alpha: float | None = None
    beta: float | None = None
    projection: bool = False
    rtol: float = 1e-9
    atol: float = 1e-12
    kernel: str = "auto"
    check_stiffness: bool = True
    divergence_limit: float | None = None

    def validated(self) -> SimulationSettings:
        """Check value ranges; raise :class:`ConfigurationError` naming the setting."""
        if self.closure not in ("penalty", "exact"):
            raise ConfigurationError(
                f"closure: expected 'penalty' or 'exact', found {self.closure!r}"
            )
        if not (np.isfinite(self.rate) and self.rate > 0):
            raise ConfigurationError(f"rate: expected a positive number of Hz, found {self.rate!r}")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ConfigurationError(
                f"substeps: expected a whole number >= 1, found {self.substeps!r}"
            )
        for key in ("kp", "kv", "omega_n", "zeta", "alpha", "beta", "rtol", "atol"):
            v = getattr(self, key)  # the fields by name: the message names the one refused
            if v is not None and not (np.isfinite(v) and v >= 0):
                raise ConfigurationError(f"{key}: expected a finite number >= 0, found {v!r}")
        if self.kernel == "numpy":
            raise ConfigurationError(
                "kernel: 'numpy' is no longer a choice (the physics runs only in the compiled "
                "kernels, as plain Python where numba is missing); use 'auto' or 'numba'"
            )
        if self.kernel not in KERNELS:
            raise ConfigurationError(
                f"kernel: expected 'auto' or 'numba', found {self.kernel!r}"
            )
        if self.kernel == "numba" and importlib.util.find_spec("numba") is None:
            raise ConfigurationError("kernel: 'numba' needs the numba package")
        make_integrator(self.integrator)  # raises with the list of known names
        return self


#: The settings a user gives on the command line, as node parameters or in a sweep.
USER_SETTINGS = ("integrator", "closure", "rate", "substeps", "kp", "kv", "omega_n", "zeta",
                 "alpha", "beta", "projection", "rtol", "atol")


def resolve_settings(
    defaults: dict,
    gains: dict,
    *,
    kernel: str = "auto",
    check_stiffness: bool = True,
    flag: Callable[[str], str] = str,
    **given: Any,
) -> SimulationSettings:
    """Settings from the values a user gave (None: not given) and the scene's defaults.

    Parameters
    ----------
    defaults, gains : dict
        The scene's run defaults (``integrator``, ``rate``, ``substeps``) and closure method and
        gains (``method``, ``alpha``, ``beta``, ``projection``; the penalty gains of the scene
        are applied by the simulator when none are given here).
    kernel, check_stiffness
        As in :class:`SimulationSettings`.
    flag : callable
        How a setting is named in error messages (``--omega-n`` for the command line).
    **given
        Any of the user-settable fields of :class:`SimulationSettings` (``integrator``,
        ``closure``, ``rate``, ``substeps``, ``kp``, ``kv``, ``omega_n``, ``zeta``, ``alpha``,
        ``beta``, ``projection``, ``rtol``, ``atol``); None or absent: not given. Rate in Hz,
        gains in N/m, N s/m, rad/s, 1/s.

    Returns
    -------
    SimulationSettings

    Raises
    ------
    ConfigurationError
        Raw and modal gains together, or a damping without a stiffness.
    TypeError
        A keyword that is not a user-settable setting.
    """
    unknown = sorted(set(given) - set(USER_SETTINGS))
    if unknown:
        raise TypeError(f"resolve_settings: unknown settings {unknown}; known: {USER_SETTINGS}")
    g = {k: v for k, v in given.items() if v is not None}
    kp, kv, omega_n, zeta = (g.get(k) for k in ("kp", "kv", "omega_n", "zeta"))
    if (kp is not None or kv is not None) and (omega_n is not None or zeta is not None):
        raise ConfigurationError(
            f"give either {flag('kp')}/{flag('kv')} or {flag('omega_n')}/{flag('zeta')}, not both"
        )
    if kv is not None and kp is None:
        raise ConfigurationError(f"{flag('kv')} needs {flag('kp')}")
    if zeta is not None and omega_n is None:
        raise ConfigurationError(f"{flag('zeta')} needs {flag('omega_n')}")
    return SimulationSettings(
        integrator=g.get("integrator") or defaults.get("integrator", "rk4"),
        closure=g.get("closure") or gains.get("method", "penalty"),
        rate=float(g.get("rate", defaults.get("rate", 1000.0))),
        substeps=int(g.get("substeps", defaults.get("substeps", 1))),
        kp=kp,
        kv=kv if kv is not None else (0.0 if kp is not None else None),
        omega_n=omega_n,
        zeta=zeta if zeta is not None else (1.0 if omega_n is not None else None),
        alpha=g.get("alpha", gains.get("alpha")),
        beta=g.get("beta", gains.get("beta")),
        projection=bool(g.get("projection", gains.get("projection", False))),
        kernel=kernel,
        check_stiffness=check_stiffness,
        **{k: g[k] for k in ("rtol", "atol") if k in g},
    )
