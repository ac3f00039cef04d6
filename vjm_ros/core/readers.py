"""Readers of a model's kinematics outside a simulation: the link frames at a configuration
(:func:`forward_kinematics`) and the motion of points given in link frames
(:func:`point_reader`), each from one call of the compiled kernel."""

from __future__ import annotations

import numpy as np

from vjm_ros.core.kinematics import Kinematics
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import GROUND, HINGE, Closure, Model, PointRef

_LAST_READER: list = [None, None]
"""The model and reader of the last :func:`forward_kinematics` call (reused for the same model)."""


def forward_kinematics(model: Model, q: np.ndarray, qd: np.ndarray | None = None) -> Kinematics:
    """Link frames (and rates, with ``qd``) of ``model`` at ``q``, from one kernel call.

    A convenience for occasional reads (set-up, drawing, a controller's target); the reader of
    the last model asked about is kept, so repeated calls on one model do not pack it again. Not
    for concurrent use from several threads (keep a :meth:`Mechanism.reader` per thread).

    Parameters
    ----------
    model : Model
    q : ndarray, shape (n,)
        Coordinates, rad or m.
    qd : ndarray, shape (n,), optional
        Rates; zero when omitted.

    Returns
    -------
    Kinematics
    """
    if _LAST_READER[0] is not model:
        _LAST_READER[:] = [model, Mechanism.reader(model)]
    return _LAST_READER[1].kinematics(q, qd)


def point_reader(model: Model, refs: list[PointRef]) -> Mechanism:
    """A reader of the motion of points given in link frames, from the kernel's closure rows.

    Each point ``P_i`` is tied to the world origin by a hinge row pair (zero gains: nothing
    acts), so that ``terms(q, qd)[1]`` gives, in rows ``2 i`` and ``2 i + 1``: ``residual`` the
    position (m), ``rate`` the velocity (m/s), ``bias`` ``Jdot qd`` (m/s^2) and ``jacobian``
    ``dP/dq``, shape (2, n); the link frames are those of ``model``.

    Parameters
    ----------
    model : Model
    refs : list of PointRef
        The points (``link = -1``: a world point, zero Jacobian).

    Returns
    -------
    Mechanism
    """
    origin = PointRef(GROUND, (0.0, 0.0))
    hinges = tuple(Closure(f"point{i}", HINGE, ref, origin) for i, ref in enumerate(refs))
    probe = Model.build(model.name, model.chains, model.links, model.joints, hinges,
                        gravity=tuple(model.gravity))
    return Mechanism.reader(probe)
