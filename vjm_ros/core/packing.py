"""The model and the closure method as the flat arrays the compiled kernels read.

Layouts in :mod:`vjm_ros.core.layout`; :func:`pack_model` builds them, as one
:class:`~vjm_ros.core.layout.PackedModel`, once per mechanism (its closure method's arrays again
when the method is replaced).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core import hub_linalg as H
from vjm_ros.core import layout
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.model import ANGLE, HINGE, SLIDER, Model

if TYPE_CHECKING:
    from collections.abc import Iterable

    from vjm_ros.core.model import Load

_KIND_CODE = {HINGE: layout.HINGE, SLIDER: layout.SLIDER, ANGLE: layout.ANGLE}


def pack_model(model: Model, method: PenaltyClosure | ExactClosure) -> layout.PackedModel:
    """The model and its closure method as the kernels read them.

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure

    Returns
    -------
    PackedModel
        :func:`pack_links`, :func:`pack_method` and :func:`chain_blocks` (layouts in
        :mod:`vjm_ros.core.layout`).
    """
    return layout.PackedModel(*pack_links(model), *pack_method(method, model), chain_blocks(model))


def pack_links(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The links and closures as the flat arrays the kernels read.

    Parameters
    ----------
    model : Model

    Returns
    -------
    lint : ndarray of int64, shape (n, 3)
        Revolute flag, first-of-chain flag, index of the chain's first link.
    lflt : ndarray, shape (n, 22)
        Base angle (rad), base origin (m), predecessor length (m), locked angle (rad) and slide
        (m), mass (kg), inertia (kg m^2), mass-centre offsets (m), damping, armature, the
        link's loads reduced, the joint's friction and stops (:mod:`vjm_ros.core.layout`).
    cint : ndarray of int64, shape (k, 4)
        Closure kind code, link of ``Pa``, target link (``-1``: ground), first row.
    cflt : ndarray, shape (k, 7)
        Local ``(s, w)`` of ``Pa`` and of the target (m), line direction, angle offset (rad).
    """
    n = model.n
    lint = np.zeros((n, 3), dtype=np.int64)
    lflt = np.zeros((n, layout.N_LFLT))
    for chain in model.chains:
        for i in chain.links:
            lint[i, layout.L_START] = chain.links[0]
    lint[:, layout.L_REV] = model.is_revolute
    lint[:, layout.L_FIRST] = model.first_of_chain
    lflt[:, layout.F_BASE_ANGLE] = model.base_angle
    lflt[:, layout.F_BASE_X : layout.F_BASE_Y + 1] = model.base_origin
    lflt[:, layout.F_PRED_LEN] = model.pred_length
    lflt[:, layout.F_LOCK_ANGLE] = model.locked_angle
    lflt[:, layout.F_LOCK_SLIDE] = model.locked_slide
    lflt[:, layout.F_MASS] = model.mass
    lflt[:, layout.F_INERTIA] = model.inertia
    lflt[:, layout.F_COM_P : layout.F_COM_Q + 1] = model.com
    lflt[:, layout.F_DAMPING] = model.damping
    lflt[:, layout.F_ARMATURE] = model.armature
    lflt[:, layout.F_FRICTION] = model.friction
    lflt[:, layout.F_FRICTION_SCALE] = model.friction_scale
    lflt[:, layout.F_RANGE_LO] = model.range_lo
    lflt[:, layout.F_RANGE_HI] = model.range_hi
    lflt[:, layout.F_RESTITUTION] = model.restitution
    add_loads(lflt, model.loads)
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
    par : ndarray, shape (8,)
        Method code (0 penalty, 1 exact), ``alpha``, ``beta`` (1/s), ``rcond``, gravity (m/s^2),
        whether the model has damping, armature, smooth friction or loads, and whether it has
        sticking friction or stops.
    """
    r = model.n_rows
    gains = np.zeros((r, 2))
    par = np.zeros(layout.N_PAR)
    if isinstance(method, PenaltyClosure):
        par[layout.P_METHOD] = layout.PENALTY
        gains[:, 0] = np.broadcast_to(np.asarray(method.kp, dtype=float), (r,))
        gains[:, 1] = np.broadcast_to(np.asarray(method.kv, dtype=float), (r,))
    else:
        par[layout.P_METHOD] = layout.EXACT
        par[layout.P_ALPHA] = method.alpha
        par[layout.P_BETA] = method.beta
        par[layout.P_RCOND] = method.rcond
    par[layout.P_GX : layout.P_GY + 1] = np.asarray(model.gravity, dtype=float).reshape(2)
    par[layout.P_PLANT] = 1.0 if model.has_plant_terms else 0.0
    par[layout.P_JOINT_EFFORTS] = 1.0 if model.has_joint_efforts else 0.0
    return gains, par


def add_loads(lflt: np.ndarray, loads: Iterable[Load]) -> None:
    """Add ``loads`` (:class:`~vjm_ros.core.model.Load`) to the load columns of ``lflt`` in
    place, reduced per link (:mod:`vjm_ros.core.layout`)."""
    for load in loads:
        i, (s, w), (fx, fy) = load.point.link, load.point.local, load.force
        lflt[i, layout.F_LOAD_FX] += fx
        lflt[i, layout.F_LOAD_FY] += fy
        lflt[i, layout.F_LOAD_A] += s * fy - w * fx
        lflt[i, layout.F_LOAD_B] -= s * fx + w * fy
        lflt[i, layout.F_LOAD_TZ] += load.torque


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



HUB_MIN_GROUPS = 4
"""Fewest chains around a hub for which :func:`closure_layout` gives a hub layout by default.

Below it the dense solves are as fast (four chains on one pin, rk4 with exact closure: 5.7 us
per tick dense, 6.4 us with the hub solves, in one run) and they keep the numbers of every
built-in scene bit for bit (``rrr_platform``, three legs around a platform, is the largest)."""


def no_hub_layout(r: int) -> np.ndarray:
    """The closure layout that asks for the dense solves (:func:`closure_layout`)."""
    lay = np.zeros((r + 1, H.N_HUB_COLUMNS), dtype=np.int64)
    lay[r, 0] = -1
    return lay


def closure_layout(model: Model, blocks: np.ndarray, min_groups: int = HUB_MIN_GROUPS
                   ) -> np.ndarray:
    """The closure rows laid out around a hub chain, where they can be.

    A row of ``A`` has non-zeros only in the chains of the two links its closure names. When one
    chain (the *hub*) is named by many closures and every row touches exactly one other chain
    (``N`` chains whose tips meet at one pin: ``N - 1`` hinges from the first tip), ``A M^-1 A^T``
    is block-diagonal by that other chain plus a term of rank at most the hub's size, and
    ``M + h A^T W A`` couples each chain only to itself and to the hub: the kernels then solve
    both in time linear in the number of chains (:mod:`vjm_ros.core.hub_linalg`).

    Parameters
    ----------
    model : Model
    blocks : ndarray of int64, shape (nb + 1,)
        :func:`chain_blocks`.
    min_groups : int
        Fewest chains besides the hub for a hub layout (:data:`HUB_MIN_GROUPS`).

    Returns
    -------
    ndarray of int64, shape (r + 1, max(5, groups + 3))
        Row ``i < r``: the other chain's block (column ``H_OTHER``), the hub's block or ``-1``
        when the row does not touch the hub (``H_HUB``), two scratch columns, and in
        ``H_ORDER`` the row in place ``i`` of the hub order (rows group by group, a group being
        the rows that touch one chain besides the hub, ascending within a group). Row ``r``:
        the hub's block (``-1``: no hub layout, the dense solves), the number of groups and
        where each group starts in the hub order.
    """
    r = model.n_rows
    nb = len(blocks) - 1
    if r == 0 or nb < min_groups + 1:
        return no_hub_layout(r)
    block_of = np.searchsorted(blocks, np.arange(model.n), side="right") - 1
    touched = []
    for closure in model.closures:
        chains = {int(block_of[link]) for link in (closure.point.link, closure.target.link)
                  if link >= 0}
        touched += [chains] * closure.rows
    counts = np.bincount([b for chains in touched for b in chains], minlength=nb)
    hub = int(np.argmax(counts))
    other = np.array([next(iter(chains - {hub})) if len(chains - {hub}) == 1 else -1
                      for chains in touched], dtype=np.int64)
    groups = sorted(set(other.tolist()))
    if -1 in groups or len(groups) < max(min_groups, 1):
        return no_hub_layout(r)
    order = [i for b in groups for i in range(r) if other[i] == b]
    starts = np.cumsum([0] + [int(np.sum(other == b)) for b in groups])
    lay = np.zeros((r + 1, max(H.N_HUB_COLUMNS, len(groups) + 3)), dtype=np.int64)
    lay[:r, H.H_OTHER] = other
    lay[:r, H.H_HUB] = [hub if hub in chains else -1 for chains in touched]
    lay[:r, H.H_ORDER] = order
    lay[r, : len(groups) + 3] = [hub, len(groups), *starts]
    return lay
