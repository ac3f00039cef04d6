"""Assembly: solve the dependent coordinates so that the closures hold.

Given the driving coordinates (kept fixed) and guesses for the others, a damped Gauss-Newton
iteration with minimum-norm steps solves ``C(q) = 0``; the rates of the free coordinates are then
corrected by the least change that makes ``A qd = 0``.
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core.model import Model


def _reader(model: Model):
    """The compiled mechanism that reads closure rows (imported here: loading the kernels is
    paid by the scenes that need them)."""
    from vjm_ros.core.mechanism import Mechanism

    return Mechanism.reader(model)


def closure_residual(model: Model, q: np.ndarray) -> np.ndarray:
    """Stacked closure residual ``C(q)`` (m or rad).

    Returns
    -------
    ndarray, shape (r,)
    """
    return _reader(model).terms(q, jacobian=False)[1].residual


def assemble(
    model: Model,
    fixed: list[int],
    tolerance: float = 1e-10,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Solve the free coordinates so that ``C(q) = 0`` and ``A qd = 0``.

    Parameters
    ----------
    model : Model
        Its initial joint values are the driving values and the guesses.
    fixed : list of int
        Coordinates that keep their given value and rate.
    tolerance : float
        Largest acceptable ``|C|`` after assembly, m or rad. At most 100 Gauss-Newton steps
        and 300 residual evaluations, line-search trials included: assemblies that succeed take
        a few dozen; the budget bounds the time spent on geometry that cannot be closed, where
        each iteration would otherwise halve its step some twenty times for little progress.

    Returns
    -------
    q, qd : ndarray, shape (n,)
    residual : float
        ``max |C|`` reached (``nan`` or ``inf`` if the guesses give a non-finite residual).

    Raises
    ------
    numpy.linalg.LinAlgError
        If a least-squares step fails (only for non-finite or absurdly scaled input).
    """
    q, qd = model.initial_state()
    if model.n_rows == 0:
        return q, qd, 0.0
    mech = _reader(model)
    free = np.setdiff1d(np.arange(model.n), np.asarray(fixed, dtype=int))

    def evaluate(qq):
        return mech.terms(qq)[1]

    terms = evaluate(q)
    err = float(np.max(np.abs(terms.residual)))
    if not np.isfinite(err):
        return q, qd, err
    evaluations = 1
    for _ in range(100):
        if err <= 0.01 * tolerance or free.size == 0:
            break
        a = terms.jacobian[:, free]
        step = np.linalg.lstsq(a, -terms.residual, rcond=1e-12)[0]
        scale = 1.0
        while scale > 1e-6 and evaluations < 300:
            trial = q.copy()
            trial[free] += scale * step
            # Trials need only the residual; the Jacobian is formed for the accepted one.
            t_res = mech.terms(trial, jacobian=False)[1].residual
            evaluations += 1
            t_err = float(np.max(np.abs(t_res)))
            if np.isfinite(t_err) and t_err < err:
                q, terms, err = trial, evaluate(trial), t_err
                break
            scale *= 0.5
        else:
            break
    terms = mech.terms(q, qd)[1]
    if free.size:
        a = terms.jacobian[:, free]
        qd = qd.copy()
        qd[free] += np.linalg.lstsq(a, -(terms.jacobian @ qd), rcond=1e-12)[0]
    return q, qd, err
