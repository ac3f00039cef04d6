"""What one evaluation of the kernels gives, as value objects over the workspace's buffers.

:class:`Evaluation` (accelerations, closure forces, energies) and :class:`DynamicsTerms`
(kinematics, mass matrix, bias, mass centres) are views of a
:class:`~vjm_ros.core.layout.Data` after :func:`vjm_ros.core.kernels.evaluate`: nothing is copied.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core import layout
from vjm_ros.core.constraints import ClosureTerms
from vjm_ros.core.kinematics import Kinematics

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


@dataclass
class DynamicsTerms:
    """Everything the equations of motion need at one state.

    Attributes
    ----------
    kin : Kinematics
    mass_matrix : ndarray, shape (n, n)
    bias : ndarray, shape (n,)
        ``b(q, qd)`` such that ``M qdd + b = tau``, N m or N.
    com : ndarray, shape (n, 2)
        Mass centres, m.
    com_velocity : ndarray, shape (n, 2)
        m/s.
    """

    kin: Kinematics
    mass_matrix: np.ndarray
    bias: np.ndarray
    com: np.ndarray
    com_velocity: np.ndarray


@dataclass
class Evaluation:
    """Every derived quantity at one state and effort.

    Attributes
    ----------
    qdd : ndarray, shape (n,)
    dyn : DynamicsTerms
    closure : ClosureTerms
    row_force : ndarray, shape (r,)
        Closure force per row (penalty force or multiplier), N or N m.
    energy : ndarray, shape (3,)
        Kinetic, gravitational and penalty-spring energy (0 for exact closures), J.
    """

    qdd: np.ndarray
    dyn: DynamicsTerms
    closure: ClosureTerms
    row_force: np.ndarray
    energy: np.ndarray = field(default_factory=lambda: np.zeros(3))


def as_vector(x: ArrayLike) -> np.ndarray:
    """A C-contiguous float64 vector (no copy when ``x`` already is one)."""
    return np.ascontiguousarray(x, dtype=np.float64)


def unpack(buffers: layout.Data, n: int) -> tuple[DynamicsTerms, ClosureTerms]:
    """The kernel's output buffers (the first seven fields of a :class:`~vjm_ros.core.layout.Data`)
    as value objects (views of the buffers, nothing copied)."""
    kin, mm, bias, cm, crow, jac, points = buffers[:7]
    rotation = np.empty((n + 1, 2, 2))
    rotation[:, 0, 0] = kin[:, layout.K_COS]
    rotation[:, 1, 0] = kin[:, layout.K_SIN]
    rotation[:, 0, 1] = -kin[:, layout.K_SIN]
    rotation[:, 1, 1] = kin[:, layout.K_COS]
    n_pred = np.empty((n, 2))
    n_pred[:, 0] = -kin[:n, layout.K_PSIN]
    n_pred[:, 1] = kin[:n, layout.K_PCOS]
    kinematics = Kinematics(
        theta=kin[:, layout.K_THETA],
        origin=kin[:, layout.K_OX : layout.K_OY + 1],
        omega=kin[:, layout.K_OMEGA],
        v_origin=kin[:, layout.K_VX : layout.K_VY + 1],
        a_origin=kin[:, layout.K_AX : layout.K_AY + 1],
        n_pred=n_pred,
        rotation=rotation,
        slide=kin[:n, layout.K_SLIDE],
    )
    dyn = DynamicsTerms(kinematics, mm, bias, cm[:, layout.C_X : layout.C_Y + 1], cm[:, layout.C_VX : layout.C_VY + 1])
    closure = ClosureTerms(
        residual=crow[:, layout.R_RES],
        rate=crow[:, layout.R_RATE],
        jacobian=jac,
        bias=crow[:, layout.R_BIAS],
        row_direction=crow[:, layout.R_DX : layout.R_DZ + 1],
        points=points,
    )
    return dyn, closure
