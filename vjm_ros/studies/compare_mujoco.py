"""The same mechanisms in MuJoCo, for the side-by-side rows of ``vjm bench``.

Optional: install with ``pip install .[compare]``. Nothing here imports :mod:`mujoco` at module
import time; :func:`import_mujoco` returns ``None`` when it is missing and the bench then leaves
the MuJoCo rows out (and says so).

The model is the scene's MJCF export (:func:`vjm_ros.formats.mjcf_out.scene_mjcf`, the one MJCF
writer: bodies nested per chain at the initial pose, ``qpos`` equal to the scene's joint
coordinates, hinge closures as ``connect``, slider and angle closures through carriage bodies,
actuators as ``motor``, sites at link ends, named points and both sides of every closure), run
from its ``initial`` keyframe, its closures' carriages of negligible mass
(:func:`~vjm_ros.formats.mjcf_out.stiffen_carriages`), so that geometry, masses, inertias and gravity are those of the
scene and the bench reads the same positions as from vjm.

MuJoCo 4.0.0 is excluded (:data:`MUJOCO_REQUIREMENT`): its sparse Cholesky factorization merges
rows with different descendants into one supernode and gives the Newton solver a wrong Hessian
factor when the constraint Jacobian is sparse (fixed in 4.0.1). Models this small use MuJoCo's
dense Jacobian (``jacobian="auto"`` picks dense below 60 degrees of freedom), so the bench's rows
are not affected, but a requirement cannot tell models apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from vjm_ros.core.errors import DivergenceError
from vjm_ros.core.model import Model
from vjm_ros.formats.mjcf_out import INITIAL_KEY, MjcfSettings, scene_mjcf, stiffen_carriages
from vjm_ros.scene.plant import Plant

MUJOCO_REQUIREMENT = "mujoco>=3.2,!=4.0.0"
"""Requirement string of the ``compare`` extra."""

KNOWN_BAD_VERSIONS = {
    "4.0.0": (
        "MuJoCo 4.0.0 has a sparse Cholesky bug (wrong Newton Hessian factor with a sparse "
        "constraint Jacobian; fixed in 4.0.1)"
    ),
}
"""Versions with a known defect that matters for this comparison, and why."""


def import_mujoco() -> ModuleType | None:
    """The :mod:`mujoco` module, or None when it is not installed."""
    try:
        import mujoco
    except ImportError:
        return None
    return mujoco


def mujoco_version() -> str | None:
    """Installed MuJoCo version, or None."""
    mj = import_mujoco()
    return None if mj is None else str(mj.__version__)


def version_note(version: str | None) -> str | None:
    """Why a MuJoCo version is not trusted for the comparison, or None when it is."""
    if version is None:
        return None
    return KNOWN_BAD_VERSIONS.get(version)


@dataclass(frozen=True)
class MujocoSettings(MjcfSettings):
    """The MJCF's solver settings (:class:`MjcfSettings`) at the bench's control rate.

    The step follows from the rate, ``timestep = 1 / (rate * substeps)``, and the carriages weigh
    ``inertia_epsilon`` (negligible: :func:`stiffen_carriages` gives them their link's constraint
    weight); neither is given.

    Attributes
    ----------
    rate : float
        Control ticks per second, Hz.
    substeps : int
        MuJoCo steps per tick.
    """

    timestep: float = field(init=False)
    carriage_mass: float | None = field(init=False)
    rate: float = 1000.0
    substeps: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "timestep", 1.0 / (self.rate * self.substeps))
        object.__setattr__(self, "carriage_mass", self.inertia_epsilon)


class MujocoSimulator:
    """Fixed-rate MuJoCo run of a scene, read through the same positions as vjm.

    Parameters
    ----------
    model : Model
    settings : MujocoSettings
    plant : Plant, optional
        The scene's actuator dynamics (default: unit gears, no lag or delay).

    Raises
    ------
    ImportError
        When MuJoCo is not installed.
    """

    def __init__(self, model: Model, settings: MujocoSettings | None = None,
                 plant: Plant | None = None):
        mj = import_mujoco()
        if mj is None:
            raise ImportError("MuJoCo is not installed (pip install '.[compare]')")
        self.mj = mj
        self.model = model
        self.settings = settings or MujocoSettings()
        self.xml = scene_mjcf(model, self.settings, plant)
        self.m = mj.MjModel.from_xml_string(self.xml)
        stiffen_carriages(self.m, model)
        self.d = mj.MjData(self.m)
        self.dt = 1.0 / self.settings.rate
        self.substeps = int(self.settings.substeps)
        self.ticks = 0
        self.t = 0.0

        def site(name: str) -> int:
            return int(mj.mj_name2id(self.m, mj.mjtObj.mjOBJ_SITE, name))

        self._ends = np.array([site(f"end_{lk.name}") for lk in model.links], dtype=int)
        self._points = np.array([site(f"pt_{p.name}") for p in model.points], dtype=int)
        self._cl_a = np.array([site(f"cl_{c.name}_a") for c in model.closures], dtype=int)
        self._cl_b = np.array([site(f"cl_{c.name}_b") for c in model.closures], dtype=int)
        self._badqacc = int(mj.mjtWarning.mjWARN_BADQACC)
        self._previous_handler = mj.get_mju_user_warning()
        self.warnings: list[str] = []
        mj.set_mju_user_warning(self.warnings.append)
        mj.mj_resetDataKeyframe(self.m, self.d, mj.mj_name2id(self.m, mj.mjtObj.mjOBJ_KEY,
                                                              INITIAL_KEY))
        mj.mj_forward(self.m, self.d)

    def close(self) -> None:
        """Restore MuJoCo's warning handler."""
        if self._previous_handler is not ...:
            self.mj.set_mju_user_warning(self._previous_handler)
            self._previous_handler = ...

    def __enter__(self) -> MujocoSimulator:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def set_efforts(self, efforts: np.ndarray) -> np.ndarray:
        """Hold actuator efforts (scene order, clamped to the scene's limits), N m or N.

        Returns
        -------
        ndarray
            The efforts as applied.
        """
        e = np.asarray(efforts, dtype=float).reshape(-1)
        limits = np.array([a.limit for a in self.model.actuators], dtype=float)
        e = np.clip(e, -limits, limits)
        self.d.ctrl[:] = e
        return e

    def power_in(self) -> float:
        """Actuator power ``tau . qd`` at the current state, W (after :meth:`refresh`)."""
        return float(self.d.qfrc_actuator @ self.d.qvel)

    def step_tick(self) -> None:
        """One control tick (``substeps`` MuJoCo steps), unchecked: what is timed."""
        self.mj.mj_step(self.m, self.d, nstep=self.substeps)

    def advance(self) -> None:
        """One control tick, then the divergence check.

        Raises
        ------
        DivergenceError
            When MuJoCo reported a bad acceleration (it then resets its state) or the state is no
            longer finite.
        """
        self.step_tick()
        self.ticks += 1
        self.t = self.ticks * self.dt
        self.check()

    def check(self) -> None:
        """Raise :class:`DivergenceError` if MuJoCo reported instability since the start."""
        if self.d.warning[self._badqacc].number > 0 or not (
            np.all(np.isfinite(self.d.qpos)) and np.all(np.isfinite(self.d.qvel))
        ):
            raise DivergenceError(
                self.t,
                "MuJoCo reported a bad acceleration (mjWARN_BADQACC) and reset its state",
                None,
                "constraint stiffness (solref) against the step, or the step too large",
            )

    def refresh(self) -> None:
        """Recompute derived quantities (positions, energy) at the current state."""
        self.mj.mj_forward(self.m, self.d)

    def link_ends(self) -> np.ndarray:
        """End point of every link, shape (n, 2), m."""
        return self.d.site_xpos[self._ends, :2].copy()

    def points(self) -> np.ndarray:
        """Named points (chain tips first), shape (n_points, 2), m."""
        return self.d.site_xpos[self._points, :2].copy()

    def closure_errors(self) -> np.ndarray:
        """Distance between the two sides of every closure, shape (k,), m."""
        if not len(self._cl_a):
            return np.zeros(0)
        diff = self.d.site_xpos[self._cl_a] - self.d.site_xpos[self._cl_b]
        return np.linalg.norm(diff, axis=1)

    def energy(self) -> tuple[float, float]:
        """Kinetic and potential (gravity) energy at the current state, J (after :meth:`refresh`)."""
        return float(self.d.energy[1]), float(self.d.energy[0])
