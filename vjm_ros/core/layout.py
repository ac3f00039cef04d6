"""The packed model and the kernels' workspace: what :mod:`vjm_ros.core.kernels` reads and writes.

Model and method arrays (fields of :class:`PackedModel`, built by
:func:`vjm_ros.core.packing.pack_model`; read-only, one value serves every thread) and the
workspace (:class:`Data`, :func:`make_data`; one per thread, nothing allocated per call). The
columns of each array are named by the constants below.


* ``lint`` int64 (n, 3): revolute flag, first-of-chain flag, index of the chain's first link;
* ``lflt`` float64 (n, 22): base angle (rad), base origin x, y (m), predecessor length (m), locked
  angle (rad), locked slide (m), mass (kg), inertia (kg m^2), mass-centre offsets ``p``, ``q`` (m),
  the joint's damping (N m s/rad or N s/m) and armature (kg m^2 or kg), then the loads on the
  link reduced to a world force ``(Fx, Fy)`` (N) at the link origin and a moment
  ``A cos(theta) + B sin(theta) + Tz`` (N m), with ``A = sum(s Fy - w Fx)`` and
  ``B = -sum(s Fx + w Fy)`` over the link's loads at local points ``(s, w)``, then the joint's
  Coulomb friction bound (N m or N) and the velocity scale of its smooth model (rad/s or m/s;
  0: sticking friction, :mod:`vjm_ros.core.joint_efforts`);
* ``cint`` int64 (k, 4): closure kind (:data:`HINGE`, :data:`SLIDER`, :data:`ANGLE`), link of
  ``Pa``, link of the target (``-1``: ground), first row;
* ``cflt`` float64 (k, 7): local ``(s, w)`` of ``Pa`` and of the target (m), line direction,
  angle offset (rad);
* ``gains`` float64 (r, 2): penalty ``Kp``, ``Kv`` per row (ignored by the exact method);
* ``par`` float64 (8,): method (0 penalty, 1 exact), Baumgarte ``alpha``, ``beta`` (1/s),
  ``rcond``, gravity ``gx``, ``gy`` (m/s^2), 1 when some joint has damping, armature or smooth
  friction or a link a load (0: the kernels skip those terms), 1 when some joint has sticking
  friction or a stop (0: no joint efforts are solved).

Output buffers (fields of :class:`Data`; columns named by the ``K_*``, ``C_*`` and ``R_*``
constants):

* ``kin`` (n + 1, 15): per link ``theta``, ``cos``, ``sin``, origin, ``omega``, origin velocity and
  bias acceleration, then ``cos``/``sin`` of the predecessor angle, the slide ``B``, the
  predecessor's ``omega`` and the slide rate; the last row is the ground;
* ``mm`` (n, n), ``bias`` (n,): ``M`` and ``b`` with ``M qdd + b = tau``;
* ``cm`` (n, 4): mass centres (m) and their velocities (m/s);
* ``crow`` (r, 7): ``C``, ``Cdot``, ``Adot qd``, row force (N or N m), world-frame force direction
  ``(Fx, Fy, Mz)`` of a unit row force;
* ``jac`` (r, n): ``A``; ``points`` (k, 2): application point ``Pa`` of each closure, m.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vjm_ros.core.hub_linalg import N_HUB_COLUMNS

# closure kinds (column 0 of cint) and closure methods (par[P_METHOD])
HINGE = 0
SLIDER = 1
ANGLE = 2

PENALTY = 0
EXACT = 1

# columns of lint
L_REV, L_FIRST, L_START = 0, 1, 2
# columns of lflt
F_BASE_ANGLE, F_BASE_X, F_BASE_Y, F_PRED_LEN, F_LOCK_ANGLE, F_LOCK_SLIDE = 0, 1, 2, 3, 4, 5
F_MASS, F_INERTIA, F_COM_P, F_COM_Q = 6, 7, 8, 9
F_DAMPING, F_ARMATURE = 10, 11
F_LOAD_FX, F_LOAD_FY, F_LOAD_A, F_LOAD_B, F_LOAD_TZ = 12, 13, 14, 15, 16
F_FRICTION, F_FRICTION_SCALE = 17, 18
F_RANGE_LO, F_RANGE_HI, F_RESTITUTION = 19, 20, 21
N_LFLT = 22
# entries of par
P_METHOD, P_ALPHA, P_BETA, P_RCOND, P_GX, P_GY, P_PLANT, P_JOINT_EFFORTS = 0, 1, 2, 3, 4, 5, 6, 7
N_PAR = 8
# columns of kin
K_THETA, K_COS, K_SIN, K_OX, K_OY, K_OMEGA, K_VX, K_VY, K_AX, K_AY = range(10)
K_PCOS, K_PSIN, K_SLIDE, K_POMEGA, K_SLIDE_RATE = range(10, 15)
N_KIN = 15
# columns of cm
C_X, C_Y, C_VX, C_VY = range(4)
N_CM = 4
# columns of crow
R_RES, R_RATE, R_BIAS, R_FORCE, R_DX, R_DY, R_DZ = range(7)
N_CROW = 7


class PackedModel(NamedTuple):
    """The model and its closure method as the kernels read them (layouts in the module
    docstring), built by :func:`vjm_ros.core.packing.pack_model`. The kernels never write it:
    one value serves every thread.

    Attributes
    ----------
    lint : ndarray of int64, shape (n, 3)
    lflt : ndarray, shape (n, 10)
    cint : ndarray of int64, shape (k, 4)
    cflt : ndarray, shape (k, 7)
    gains : ndarray, shape (r, 2)
    par : ndarray, shape (6,)
    blocks : ndarray of int64, shape (nb + 1,)
        Boundaries ``0, ..., n`` of the mass matrix's diagonal blocks, one per chain
        (:func:`vjm_ros.core.packing.chain_blocks`).
    """

    lint: np.ndarray
    lflt: np.ndarray
    cint: np.ndarray
    cflt: np.ndarray
    gains: np.ndarray
    par: np.ndarray
    blocks: np.ndarray


class Data(NamedTuple):
    """What the kernels write: the terms of the last evaluation and the scratch arrays of the
    solves (:func:`make_data`). One per thread; nothing is allocated per call.

    Attributes
    ----------
    kin, mm, bias, cm, crow, jac, points : ndarray
        The terms of the last evaluation, shapes (n + 1, 15), (n, n), (n,), (n, 4), (r, 7),
        (r, n), (k, 2) (module docstring).
    lu : ndarray, shape (n, n)
        LU factors of ``M`` (or of ``M + h A^T W A``).
    piv : ndarray of int64, shape (n,)
        Their pivots.
    minv_at : ndarray, shape (n, r)
        ``M^-1 A^T``.
    g, v : ndarray, shape (r, r)
        ``A M^-1 A^T`` and its eigenvectors.
    vec : ndarray, shape (3 + r + nh, max(n, r, nh + 1))
        Vectors of the solves (row 0: the multipliers; ``nh`` the hub chain's size).
    rhs : ndarray, shape (r,)
        Right-hand side of the closure solves.
    corr : ndarray, shape (n,)
        The correction they give.
    ks, vs : ndarray, shape (4, n)
        Stage accelerations and velocities of a step.
    qi : ndarray, shape (n,)
        Stage coordinates.
    scratch : ndarray, shape (n,)
        Accelerations of a step's stage.
    spare : ndarray, shape (n,)
        Unread second output of the entry points that have one output.
    zero : ndarray, shape (n,)
        Zeros (the rates of the evaluations without any).
    touch : ndarray of int64, shape (r, max(nb, 1))
        Diagonal blocks each closure row touches.
    layout : ndarray of int64, shape (r + 1, c)
        The closure layout (:func:`vjm_ros.core.packing.closure_layout`, a copy: the hub solves
        write its scratch columns).
    wcols : ndarray, shape (n, n)
        Rows of the closed mechanism's inverse mass matrix for the joints with sticking friction
        (:mod:`vjm_ros.core.joint_efforts`).
    column : ndarray, shape (n,)
        The rates at the start of a step with friction.
    impulse : ndarray, shape (n + 1,)
        The friction effort of each joint over the last step (N m or N); at ``n``, the energy
        the friction and the stops (their impacts included) took over the last call's steps
        (J).
    stop : ndarray, shape (n,)
        The effort of each joint's stops over the last step, N m or N.
    """

    kin: np.ndarray
    mm: np.ndarray
    bias: np.ndarray
    cm: np.ndarray
    crow: np.ndarray
    jac: np.ndarray
    points: np.ndarray
    lu: np.ndarray
    piv: np.ndarray
    minv_at: np.ndarray
    g: np.ndarray
    v: np.ndarray
    vec: np.ndarray
    rhs: np.ndarray
    corr: np.ndarray
    ks: np.ndarray
    vs: np.ndarray
    qi: np.ndarray
    scratch: np.ndarray
    spare: np.ndarray
    zero: np.ndarray
    touch: np.ndarray
    layout: np.ndarray
    wcols: np.ndarray
    column: np.ndarray
    impulse: np.ndarray
    stop: np.ndarray


def output_shapes(model: PackedModel) -> tuple[tuple[int, ...], ...]:
    """Shapes of ``kin, mm, bias, cm, crow, jac, points`` for ``model``."""
    n, r, k = model.lint.shape[0], model.gains.shape[0], model.cint.shape[0]
    return ((n + 1, N_KIN), (n, n), (n,), (n, N_CM), (r, N_CROW), (r, n), (k, 2))


def make_data(model: PackedModel, layout: np.ndarray | None = None) -> Data:
    """A workspace of the kernels for ``model`` (built in Python once per mechanism and thread:
    compiled callers receive it, so nothing is allocated per call).

    Parameters
    ----------
    model : PackedModel
    layout : ndarray of int64, optional
        :func:`vjm_ros.core.packing.closure_layout` (copied); omitted, no hub layout (the dense
        solves).
    """
    n, r = model.lint.shape[0], model.gains.shape[0]
    blocks = model.blocks
    if layout is None:
        layout = np.zeros((r + 1, N_HUB_COLUMNS), dtype=np.int64)
        layout[r, 0] = -1
    lay = np.array(layout, dtype=np.int64)
    hub = lay[r, 0]
    nh = int(blocks[hub + 1] - blocks[hub]) if hub >= 0 else 0
    m = max(n, r, nh + 1)
    outputs = [np.empty(shape) for shape in output_shapes(model)]
    return Data(*outputs, lu=np.empty((n, n)), piv=np.empty(n, dtype=np.int64),
                minv_at=np.empty((n, r)), g=np.empty((r, r)), v=np.empty((r, r)),
                vec=np.zeros((3 + r + nh, m)), rhs=np.empty(r), corr=np.empty(n),
                ks=np.zeros((4, n)), vs=np.zeros((4, n)), qi=np.empty(n), scratch=np.empty(n),
                spare=np.empty(n), zero=np.zeros(n),
                touch=np.zeros((r, max(len(blocks) - 1, 1)), dtype=np.int64), layout=lay,
                wcols=np.zeros((n, n)), column=np.zeros(n), impulse=np.zeros(n + 1),
                stop=np.zeros(n))


def as_arguments(value: PackedModel | Data) -> tuple:
    """A :class:`PackedModel` or :class:`Data` as the plain tuple of its fields that the compiled
    functions take: numba types a plain tuple of arrays in its dispatcher's C code, a named one
    in Python (some 3 µs more per call of :func:`step` from Python, measured on the four-bar)."""
    return tuple(value)
