"""The model and the closure method as the flat arrays the compiled kernels read.

Layouts in :mod:`vjm_ros.core.kernels`; the arrays are built once per mechanism (and again when
its closure method is replaced).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.model import ANGLE, HINGE, SLIDER, Model

_KIND_CODE = {HINGE: K.HINGE, SLIDER: K.SLIDER, ANGLE: K.ANGLE}


def pack_model(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The model as the flat arrays the kernels read (layout in :mod:`vjm_ros.core.kernels`).

    Parameters
    ----------
    model : Model

    Returns
    -------
    lint : ndarray of int64, shape (n, 3)
        Revolute flag, first-of-chain flag, index of the chain's first link.
    lflt : ndarray, shape (n, 10)
        Base angle (rad), base origin (m), predecessor length (m), locked angle (rad) and slide
        (m), mass (kg), inertia (kg m^2), mass-centre offsets (m).
    cint : ndarray of int64, shape (k, 4)
        Closure kind code, link of ``Pa``, target link (``-1``: ground), first row.
    cflt : ndarray, shape (k, 7)
        Local ``(s, w)`` of ``Pa`` and of the target (m), line direction, angle offset (rad).
    """
    n = model.n
    lint = np.zeros((n, 3), dtype=np.int64)
    lflt = np.zeros((n, K.N_LFLT))
    for chain in model.chains:
        for i in chain.links:
            lint[i, K.L_START] = chain.links[0]
    lint[:, K.L_REV] = model.is_revolute
    lint[:, K.L_FIRST] = model.first_of_chain
    lflt[:, K.F_BASE_ANGLE] = model.base_angle
    lflt[:, K.F_BASE_X : K.F_BASE_Y + 1] = model.base_origin
    lflt[:, K.F_PRED_LEN] = model.pred_length
    lflt[:, K.F_LOCK_ANGLE] = model.locked_angle
    lflt[:, K.F_LOCK_SLIDE] = model.locked_slide
    lflt[:, K.F_MASS] = model.mass
    lflt[:, K.F_INERTIA] = model.inertia
    lflt[:, K.F_COM_P : K.F_COM_Q + 1] = model.com
    k = len(model.closures)
    cint = np.zeros((k, 4), dtype=np.int64)
    cflt = np.zeros((k, 7))
    row = 0
    for c, closure in enumerate(model.closures):
        cint[c] = (_KIND_CODE[closure.kind], closure.point.link, closure.target.link, row)
        cflt[c, 0:2] = closure.point.local
        cflt[c, 2:4] = closure.target.local
        cflt[c, 4:6] = closure.direction
        cflt[c, 6] = closure.offset
        row += closure.rows
    return lint, lflt, cint, cflt


def pack_method(
    method: PenaltyClosure | ExactClosure, model: Model
) -> tuple[np.ndarray, np.ndarray]:
    """The closure method (and gravity) as kernel arrays.

    Parameters
    ----------
    method : PenaltyClosure or ExactClosure
    model : Model

    Returns
    -------
    gains : ndarray, shape (r, 2)
        Penalty ``Kp`` (N/m, N m/rad) and ``Kv`` (N s/m, N m s/rad) per row; zero for the exact
        method.
    par : ndarray, shape (6,)
        Method code (0 penalty, 1 exact), ``alpha``, ``beta`` (1/s), ``rcond``, gravity (m/s^2).
    """
    r = model.n_rows
    gains = np.zeros((r, 2))
    par = np.zeros(K.N_PAR)
    if isinstance(method, PenaltyClosure):
        par[K.P_METHOD] = K.PENALTY
        gains[:, 0] = np.broadcast_to(np.asarray(method.kp, dtype=float), (r,))
        gains[:, 1] = np.broadcast_to(np.asarray(method.kv, dtype=float), (r,))
    else:
        par[K.P_METHOD] = K.EXACT
        par[K.P_ALPHA] = method.alpha
        par[K.P_BETA] = method.beta
        par[K.P_RCOND] = method.rcond
    par[K.P_GX : K.P_GY + 1] = np.asarray(model.gravity, dtype=float).reshape(2)
    return gains, par


def chain_blocks(model: Model) -> np.ndarray:
    """Boundaries of the mass matrix's diagonal blocks, one block per chain.

    Chains are independent open chains (closures act only through forces), so ``M`` has no
    entry between coordinates of two chains.

    Returns
    -------
    ndarray of int64, shape (chains + 1,)
        ``0, start of chain 2, ..., n``.
    """
    first = np.asarray(model.first_of_chain, dtype=bool)
    starts = [i for i in range(model.n) if first[i]]
    if not starts or starts[0] != 0:
        starts = [0] + starts
    return np.array(starts + [model.n], dtype=np.int64)

