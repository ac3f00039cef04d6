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

Fixed-step methods derive every stability quantity from their own ``step`` applied to linear test
systems, so a new method needs no hand-written bound:

* :meth:`FixedStepIntegrator.amplification` / :meth:`~FixedStepIntegrator.stability_bounds`: the
  damped oscillator ``x'' + 2 zeta omega_n x' + omega_n^2 x = 0`` (valid for every method,
  including partitioned ones such as semi-implicit Euler);
* :meth:`FixedStepIntegrator.step_matrix`: a coupled linear system ``x'' = -K x - D x'``;
* :meth:`FixedStepIntegrator.stability_function`: ``R(z)`` of the scalar test equation
  ``y' = z y`` for complex ``z`` (methods that step ``(q, qd)`` as one first-order system,
  i.e. Runge-Kutta methods), and :meth:`~FixedStepIntegrator.stability_ray_bound`, the extent of
  the region ``|R(z)| <= 1`` along a ray of the complex plane.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

STABILITY_TOL = 1e-12
"""Spectral radius above ``1 + STABILITY_TOL`` counts as growth (round-off allowance)."""

_SCAN = np.linspace(1e-3, 10.0, 1000)
"""Scan of ``omega_n h`` (or ``|z|``) before bisection; bounds beyond 10 count as unbounded."""


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
        system,
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
        return np.inf

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
        return np.array([self.stability_bound(float(z)) for z in np.ravel(zeta)], dtype=float)

    def reset(self) -> None:  # noqa: B027 (optional hook: most methods keep no state)
        """Forget any state kept between ticks (after a jump of the state)."""


class FixedStepIntegrator(Integrator):
    """A method defined by one step ``step(system, q, qd, tau, h)``."""

    @abstractmethod
    def step(self, system, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float):
        """One step of length ``h``; returns ``(q, qd)``."""

    def advance(self, system, t, q, qd, tau, dt, substeps=1):
        h = dt / substeps
        for _ in range(substeps):
            q, qd = self.step(system, q, qd, tau, h)
        return q, qd

    # ------------------------------------------------------------------ linear stability
    def oscillator_radius(self, x: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        """Spectral radius of one step on damped oscillators, many at once.

        The oscillator ``x'' + 2 zeta omega_n x' + omega_n^2 x = 0`` stepped with
        ``omega_n h = x``; the method's own ``step`` advances all of them together (as
        independent coordinates with ``omega_n = x`` and ``h = 1``, the same map up to a
        scaling of the velocity).

        Parameters
        ----------
        x : array_like, shape (m,)
            ``omega_n h`` (dimensionless, >= 0).
        zeta : array_like, shape (m,) or scalar
            Damping ratios.

        Returns
        -------
        ndarray, shape (m,)
            Largest modulus of the eigenvalues of the 2 x 2 one-step map.
        """
        x = np.atleast_1d(np.asarray(x, dtype=float))
        zeta = np.broadcast_to(np.asarray(zeta, dtype=float), x.shape)
        osc = _Oscillator(x * x, 2.0 * zeta * x)
        one, zero = np.ones_like(x), np.zeros_like(x)
        q1, v1 = self.step(osc, one, zero, zero, 1.0)
        q2, v2 = self.step(osc, zero, one, zero, 1.0)
        maps = np.stack((np.stack((q1, q2), -1), np.stack((v1, v2), -1)), -2)
        return np.max(np.abs(np.linalg.eigvals(maps)), axis=-1)

    def amplification(self, x: float, zeta: float) -> float:
        """Spectral radius of one step on ``x'' + 2 zeta x' + x = 0`` with step ``h = x``."""
        return float(self.oscillator_radius(np.array([x]), zeta)[0])

    def stability_bound(self, zeta: float) -> float:
        """Largest ``omega_n h`` with spectral radius <= 1, by scan and bisection (max 10)."""
        return float(self.stability_bounds(np.array([zeta]))[0])

    def stability_bounds(self, zeta: np.ndarray) -> np.ndarray:
        """Largest stable ``omega_n h`` for each damping ratio, by scan and bisection (max 10).

        The scan over ``omega_n h`` in ``(0, 10]`` finds the first growing step; 60 bisections
        between the last stable and the first growing value follow. A subclass that overrides
        :meth:`stability_bound` (an unconditionally stable method) is asked value by value.
        ``zeta``: damping ratios, shape (m,); returns the bounds on ``omega_n h``, shape (m,),
        ``inf`` where no growth is found up to 10.
        """
        if type(self).stability_bound is not FixedStepIntegrator.stability_bound:
            return super().stability_bounds(zeta)
        zeta = np.ravel(np.asarray(zeta, dtype=float))
        return _first_growth(
            lambda x, rows: self.oscillator_radius(x, zeta[rows]), zeta.size
        )

    def step_matrix(self, stiffness: np.ndarray, damping: np.ndarray, h: float) -> np.ndarray:
        """One step of the method on the linear system ``x'' = -K x - D x'`` as a matrix.

        Parameters
        ----------
        stiffness : ndarray, shape (p, p)
            ``K``, 1/s^2.
        damping : ndarray, shape (p, p)
            ``D``, 1/s.
        h : float
            Step, s.

        Returns
        -------
        ndarray, shape (2p, 2p)
            ``P`` with ``(x, x')+ = P (x, x')``; the method is stable on the system when every
            eigenvalue of ``P`` has modulus <= 1.
        """
        k = np.asarray(stiffness, dtype=float)
        p = k.shape[0]
        system = _LinearSystem(k, np.asarray(damping, dtype=float))
        out = np.zeros((2 * p, 2 * p))
        zero = np.zeros(p)
        for j in range(2 * p):
            e = np.zeros(2 * p)
            e[j] = 1.0
            x, v = self.step(system, e[:p], e[p:], zero, h)
            out[:p, j], out[p:, j] = x, v
        return out

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        """``R(z)``: one step of unit length on ``y' = z y`` maps ``y`` to ``R(z) y``.

        Computed from the method's own step with ``y`` carried by the velocity
        (``qd'' = z qd`` seen as ``qd' = a(q, qd) = z qd``; complex ``z`` as a real 2 x 2
        block). For a Runge-Kutta method (``explicit_euler``, ``rk4``) this is its stability
        function and the step on any linear system ``y' = J y`` is ``R(h J)``. A partitioned
        method (``semi_implicit_euler``) has no scalar stability function: this then returns the
        function of its velocity update only, and its stability on a mode depends on both roots
        of the mode (use :meth:`amplification` or :meth:`step_matrix`).

        Parameters
        ----------
        z : array_like of complex, shape (m,)
            ``h mu`` (dimensionless).

        Returns
        -------
        ndarray of complex, shape (m,)
        """
        z = np.atleast_1d(np.asarray(z, dtype=complex))
        m = z.size
        system = _ScalarTest(z.real, z.imag)
        qd = np.concatenate((np.ones(m), np.zeros(m)))
        _, v = self.step(system, np.zeros(2 * m), qd, np.zeros(2 * m), 1.0)
        return v[:m] + 1j * v[m:]

    def stability_ray_bound(self, angle: float) -> float:
        """Extent of the stability region ``|R(z)| <= 1`` along the ray ``z = s exp(i angle)``.

        Scan and bisection as in :meth:`stability_bounds`. Along the negative real axis
        (``angle = pi``) this is the largest stable ``h |mu|`` of a real decay rate ``mu``; along
        the imaginary axis (``angle = pi / 2``) that of an undamped oscillation. Meaningful for
        methods with a stability function (see :meth:`stability_function`).

        Parameters
        ----------
        angle : float
            Direction in the complex plane, rad (``pi / 2`` to ``pi`` for decaying modes).

        Returns
        -------
        float
            Largest ``s`` (dimensionless) with ``|R(s exp(i angle))| <= 1 + STABILITY_TOL`` from 0
            up to it; ``inf`` when no growth is found up to 10.
        """
        direction = np.exp(1j * angle)
        return float(
            _first_growth(lambda s, rows: np.abs(self.stability_function(s * direction)), 1)[0]
        )


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


class _Oscillator:
    """Independent test oscillators ``x'' = -k x - d x'`` seen through the system interface."""

    def __init__(self, stiffness: np.ndarray, damping: np.ndarray):
        self.stiffness = stiffness
        self.damping = damping

    def accelerations(self, q, qd, tau):
        return -self.stiffness * q - self.damping * qd


class _LinearSystem:
    """The coupled linear system ``x'' = -K x - D x'`` seen through the system interface."""

    def __init__(self, stiffness: np.ndarray, damping: np.ndarray):
        self.stiffness = stiffness
        self.damping = damping

    def accelerations(self, q, qd, tau):
        return -(self.stiffness @ q) - self.damping @ qd


class _ScalarTest:
    """``qd' = z qd`` for complex ``z = a + i b``, the velocity stored as ``(Re, Im)`` blocks."""

    def __init__(self, re: np.ndarray, im: np.ndarray):
        self.re = re
        self.im = im

    def accelerations(self, q, qd, tau):
        m = self.re.size
        u, v = qd[:m], qd[m:]
        return np.concatenate((self.re * u - self.im * v, self.im * u + self.re * v))
