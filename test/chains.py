"""Random chain builders and an independent chain geometry for the physics tests.

The geometry here is written from docs/design.md section 1 alone, as a plain loop over each chain, and
reads only the scene description (chains, links, joints); it never uses the index arrays that
``Model.build`` derives nor anything in ``vjm_ros.core.kinematics``:

    theta_1 = chain angle, O_1 = chain origin, a_1 = chain length
    O_(j+1) = O_j + a_j u(theta_j) + B_j n(theta_j)
    theta_(j+1) = theta_j + phi_j
    c_i = O_i + p_i u(theta_i) + q_i n(theta_i)

with ``(phi_j, B_j)`` = (q, locked slide) for a revolute joint and (locked angle, q) for a
prismatic one. Rates come from central differences along the motion ``q + s qd``.
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core.model import GROUND, PRISMATIC, REVOLUTE, Chain, Joint, Link, Model


def u(theta):
    """Unit vector along the link, ``(cos, sin)``."""
    return np.array([np.cos(theta), np.sin(theta)])


def n(theta):
    """Unit normal of the link, ``(-sin, cos)``."""
    return np.array([-np.sin(theta), np.cos(theta)])


def frames(model: Model, q):
    """Origin and absolute angle of every moving link, by the loop of docs/design.md section 1.

    Returns
    -------
    origins : ndarray, shape (n, 2)
    angles : ndarray, shape (n,)
    """
    origins = np.zeros((len(model.links), 2))
    angles = np.zeros(len(model.links))
    for chain in model.chains:
        o = np.array(chain.origin, dtype=float)
        theta = chain.angle
        a_prev = chain.length
        for i in chain.links:
            joint = model.joints[i]
            if joint.kind == REVOLUTE:
                phi, slide = q[i], joint.slide
            else:
                phi, slide = joint.angle, q[i]
            o = o + a_prev * u(theta) + slide * n(theta)
            theta = theta + phi
            origins[i] = o
            angles[i] = theta
            a_prev = model.links[i].length
    return origins, angles


def point_on_link(model: Model, q, link: int, local):
    """World position of ``O_link + s u + w n`` (``local`` = (s, w)); ground points as given."""
    if link == GROUND:
        return np.array(local, dtype=float)
    origins, angles = frames(model, q)
    s, w = local
    return origins[link] + s * u(angles[link]) + w * n(angles[link])


def mass_centres(model: Model, q):
    """Mass centre of every link and every link angle.

    Returns
    -------
    centres : ndarray, shape (n, 2)
    angles : ndarray, shape (n,)
    """
    origins, angles = frames(model, q)
    centres = np.zeros_like(origins)
    for i, link in enumerate(model.links):
        p, w = link.com
        centres[i] = origins[i] + p * u(angles[i]) + w * n(angles[i])
    return centres, angles


# Step of the central difference that turns positions into rates. The positions are sums of
# terms L cos/sin(theta) with L ~ 1 m, so the truncation error is ~ VEL_STEP^2/6 |qd|^3 L ~ 1e-12
# and the round-off ~ 1e-16 L / VEL_STEP ~ 1e-10; both far below the tolerances of the tests.
VEL_STEP = 1e-5


def rates(model: Model, q, qd):
    """Mass-centre velocities and angular velocities, by central differences along ``qd``."""
    cp, ap = mass_centres(model, q + VEL_STEP * qd)
    cm, am = mass_centres(model, q - VEL_STEP * qd)
    return (cp - cm) / (2 * VEL_STEP), (ap - am) / (2 * VEL_STEP)


def kinetic(model: Model, q, qd) -> float:
    """``T = sum 1/2 m |v_c|^2 + 1/2 I omega^2`` from :func:`rates`."""
    vc, om = rates(model, q, qd)
    total = 0.0
    for i, link in enumerate(model.links):
        total += 0.5 * link.mass * float(vc[i] @ vc[i]) + 0.5 * link.inertia * om[i] ** 2
    return total


def potential(model: Model, q) -> float:
    """``V = -sum m g . c``."""
    centres, _ = mass_centres(model, q)
    g = np.asarray(model.gravity, dtype=float)
    return -sum(link.mass * float(g @ centres[i]) for i, link in enumerate(model.links))


def random_model(
    rng: np.random.Generator,
    n_links: int,
    n_chains: int = 1,
    gravity=(0.0, -9.81),
    p_revolute: float = 0.6,
    sizes=None,
):
    """A model of ``n_chains`` open chains sharing ``n_links`` moving links.

    Every link gets a random length, mass (> 0), inertia (> 0, so that ``M`` is positive
    definite) and mass-centre offset ``(p, q)``; every joint is revolute with probability
    ``p_revolute``, else prismatic, with random initial values for its active and its locked
    coordinate. ``sizes`` (links per chain) overrides the random split of the links.
    """
    if sizes is None:
        n_chains = max(1, min(n_chains, n_links))
        cuts = np.sort(rng.choice(np.arange(1, n_links), size=n_chains - 1, replace=False))
        sizes = np.diff(np.concatenate(([0], cuts, [n_links]))).astype(int)
    chains, links, joints = [], [], []
    k = 0
    for c, size in enumerate(sizes):
        idx = []
        for _ in range(size):
            length = float(rng.uniform(0.2, 1.2))
            links.append(
                Link(
                    name=f"l{k}",
                    chain=c,
                    length=length,
                    mass=float(rng.uniform(0.3, 3.0)),
                    inertia=float(rng.uniform(0.01, 0.3)),
                    com=(float(rng.uniform(-0.2, 1.2) * length), float(rng.uniform(-0.3, 0.3))),
                )
            )
            kind = REVOLUTE if rng.random() < p_revolute else PRISMATIC
            joints.append(
                Joint(
                    name=f"j{k}",
                    kind=kind,
                    angle=float(rng.uniform(-np.pi, np.pi)),
                    slide=float(rng.uniform(-0.5, 0.5)),
                    velocity=float(rng.uniform(-2.0, 2.0)),
                )
            )
            idx.append(k)
            k += 1
        chains.append(
            Chain(
                name=f"c{c}",
                origin=(float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1))),
                angle=float(rng.uniform(-np.pi, np.pi)),
                length=float(rng.uniform(0.0, 0.5)),
                links=tuple(idx),
            )
        )
    return Model.build("random", tuple(chains), tuple(links), tuple(joints), gravity=gravity)


def random_state(rng: np.random.Generator, model: Model, speed: float = 2.0):
    """Random coordinates (angles in (-pi, pi), slides in (-0.5, 0.5) m) and rates."""
    q = np.where(
        model.is_revolute,
        rng.uniform(-np.pi, np.pi, model.n),
        rng.uniform(-0.5, 0.5, model.n),
    )
    qd = rng.uniform(-speed, speed, model.n)
    return q, qd


def coordinate_jacobian(fun, q, step: float):
    """Central-difference Jacobian of ``fun(q)`` (any array shape) with respect to ``q``.

    Returns
    -------
    ndarray, shape fun(q).shape + (len(q),)
    """
    cols = []
    for k in range(len(q)):
        e = np.zeros(len(q))
        e[k] = step
        cols.append((np.asarray(fun(q + e)) - np.asarray(fun(q - e))) / (2 * step))
    return np.stack(cols, axis=-1)


# Step of the central differences of positions in q. Positions are trigonometric in q with
# lengths ~ 1 m: truncation ~ step^2/6 ~ 2e-11 m/rad, round-off ~ 1e-16/step ~ 1e-11.
JAC_STEP = 1e-5


def mass_matrix_fd(model: Model, q):
    """``M = sum m J_c^T J_c + I J_w^T J_w`` with Jacobians by central differences."""
    jc = coordinate_jacobian(lambda x: mass_centres(model, x)[0], q, JAC_STEP)  # (n, 2, n)
    jw = coordinate_jacobian(lambda x: mass_centres(model, x)[1], q, JAC_STEP)  # (n, n)
    out = np.zeros((model.n, model.n))
    for i, link in enumerate(model.links):
        out += link.mass * jc[i].T @ jc[i] + link.inertia * np.outer(jw[i], jw[i])
    return out


def potential_gradient_fd(model: Model, q):
    """``dV/dq`` by central differences of :func:`potential`."""
    return coordinate_jacobian(lambda x: np.array(potential(model, x)), q, JAC_STEP)
