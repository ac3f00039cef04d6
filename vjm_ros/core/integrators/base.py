"""Integrator contract.

An integrator advances a :class:`~vjm_ros.core.mechanism.Mechanism` over one control tick of length
``dt`` with the efforts ``tau`` held constant (docs/design.md section 3):

1. ``advance(system, t, q, qd, tau, dt, substeps)`` returns ``(q, qd)`` at ``t + dt``;
2. fixed-step methods take ``substeps`` equal steps ``h = dt / substeps``;
3. adaptive methods ignore ``substeps`` and control their own step; their state never carries
   a derivative computed with another tick's efforts;
4. ``stability_bound(zeta)`` is the largest ``omega_n h`` for which the method keeps a linear
   oscillator of damping ratio ``zeta`` from growing (``inf`` when unconditionally stable),
   used to refuse penalty gains the step cannot carry.

A fixed-step method runs only in the compiled kernel (:meth:`Mechanism.advance_fixed
<vjm_ros.core.mechanism.Mechanism.advance_fixed>`, :func:`vjm_ros.core.kernels.step`); its class
names it there (``kernel_method``) and gives, in closed form from the method's definition, its
one-step map on the linear system ``x'' = -K x - D x'``
(:meth:`FixedStepIntegrator.step_matrix`). ``test/test_integrators.py`` checks that map against
the kernel's own steps on a mechanism whose closure dynamics are exactly linear, and the
stability bounds are computed from it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from typing import Protocol

    class System(Protocol):
        """What the integrators call of a :class:`~vjm_ros.core.mechanism.Mechanism` (a layer
        above this one)."""

        def accelerations(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
            ...

        def advance_fixed(self, method: int, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
                          h: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
            ...

STABILITY_TOL = 1e-12
"""Spectral radius above ``1 + STABILITY_TOL`` counts as growth (round-off allowance)."""

_SCAN = np.linspace(1e-3, 10.0, 1000)
"""Scan of ``omega_n h`` before bisection; bounds beyond 10 count as unbounded."""


class Integrator(ABC):
    """Base class of all time-stepping methods.

    Attributes
    ----------
    name : str
        Registry key.
    order : int
        Global order of accuracy of the method on smooth problems.
    fixed_step : bool
        True for methods with a fixed step ``h = dt / substeps``.
    """

    name: str = ""
    order: int = 0
    fixed_step: bool = True

    @abstractmethod
    def advance(
        self,
        system: System,
        t: float,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        dt: float,
        substeps: int = 1,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Advance one control tick; see the module docstring."""

    def stability_bound(self, zeta: float) -> float:
        """Largest stable ``omega_n h`` for a linear oscillator with damping ratio ``zeta``."""
        return float(self.stability_bounds(np.array([zeta]))[0])

    def stability_bounds(self, zeta: np.ndarray) -> np.ndarray:
        """:meth:`stability_bound` for each damping ratio.

        Parameters
        ----------
        zeta : array_like, shape (m,)
            Damping ratios (dimensionless, >= 0).

        Returns
        -------
        ndarray, shape (m,)
            Largest stable ``omega_n h`` per ratio (``inf`` when unbounded).
        """
        return np.full(np.size(zeta), np.inf)

    def reset(self) -> None:  # noqa: B027 (optional hook: most methods keep no state)
        """Forget any state kept between ticks (after a jump of the state)."""


class FixedStepIntegrator(Integrator):
    """A method of the compiled kernel, with its one-step map on linear systems.

    Attributes
    ----------
    kernel_method : int
        The method's code in :func:`vjm_ros.core.kernels.step`.
    """

    kernel_method: int = -1

    def advance(self, system: System, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
                dt: float, substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """``substeps`` steps of ``h = dt / substeps`` in one compiled call on ``system`` (a
        :class:`~vjm_ros.core.mechanism.Mechanism`); returns ``(q, qd)``."""
        return system.advance_fixed(self.kernel_method, q, qd, tau, dt / substeps, substeps)

    @abstractmethod
    def step_matrix(self, stiffness: np.ndarray, damping: np.ndarray, h: float) -> np.ndarray:
        """One step of the method on the linear system ``x'' = -K x - D x'`` as a matrix.

        Parameters
        ----------
        stiffness : ndarray, shape (..., p, p)
            ``K``, 1/s^2 (a stack of systems allowed).
        damping : ndarray, shape (..., p, p)
            ``D``, 1/s.
        h : float
            Step, s.

        Returns
        -------
        ndarray, shape (..., 2p, 2p)
            ``P`` with ``(x, x')+ = P (x, x')``; the method is stable on the system when every
            eigenvalue of ``P`` has modulus <= 1.
        """

    def stability_bounds(self, zeta: np.ndarray) -> np.ndarray:
        """Largest stable ``omega_n h`` for each damping ratio, by scan and bisection (max 10).

        The oscillator ``x'' + 2 zeta omega_n x' + omega_n^2 x = 0`` is stepped by
        :meth:`step_matrix` with ``h = 1`` and ``omega_n = omega_n h``. The scan over
        ``omega_n h`` in ``(0, 10]`` finds the first growing step (spectral radius above
        ``1 + STABILITY_TOL``); 60 bisections between the last stable and the first growing
        value follow. ``zeta``: damping ratios, shape (m,); returns the bounds, shape (m,),
        ``inf`` where no growth is found up to 10.
        """
        zeta = np.ravel(np.asarray(zeta, dtype=float))

        def radius(x: np.ndarray, rows: np.ndarray) -> np.ndarray:
            k = (x * x)[:, None, None]
            d = (2.0 * zeta[rows] * x)[:, None, None]
            return np.max(np.abs(np.linalg.eigvals(self.step_matrix(k, d, 1.0))), axis=-1)

        return _first_growth(radius, zeta.size)


def first_order(stiffness: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """``J = [[0, I], [-K, -D]]`` of ``x'' = -K x - D x'`` as ``y' = J y``, ``y = (x, x')``.

    Parameters
    ----------
    stiffness, damping : ndarray, shape (..., p, p)
        ``K`` (1/s^2) and ``D`` (1/s).

    Returns
    -------
    ndarray, shape (..., 2p, 2p)
    """
    k = np.asarray(stiffness, dtype=float)
    d = np.asarray(damping, dtype=float)
    eye = np.broadcast_to(np.eye(k.shape[-1]), k.shape)
    return blocks(np.zeros_like(k), eye, -k, -d)


def blocks(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``[[a, b], [c, d]]`` of stacks of square blocks, shape (..., 2p, 2p)."""
    return np.concatenate((np.concatenate((a, b), -1), np.concatenate((c, d), -1)), -2)


def _first_growth(radius, m: int) -> np.ndarray:
    """First ``s`` in ``(0, 10]`` where ``radius(s, rows) > 1 + STABILITY_TOL``, per problem.

    ``radius(s, rows)`` evaluates problem ``rows[i]`` at ``s[i]``. Scans :data:`_SCAN`, then
    bisects 60 times between the last stable and the first growing value.
    """
    n = _SCAN.size
    rows = np.repeat(np.arange(m), n)
    grows = (radius(np.tile(_SCAN, m), rows) > 1.0 + STABILITY_TOL).reshape(m, n)
    out = np.full(m, np.inf)
    todo = np.flatnonzero(grows.any(axis=1))
    if todo.size == 0:
        return out
    first = np.argmax(grows[todo], axis=1)
    hi = _SCAN[first]
    lo = np.where(first > 0, _SCAN[np.maximum(first - 1, 0)], 0.0)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        bad = radius(mid, todo) > 1.0 + STABILITY_TOL
        hi = np.where(bad, mid, hi)
        lo = np.where(bad, lo, mid)
    out[todo] = lo
    return out
