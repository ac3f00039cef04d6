"""Generated scenes of any size: a chain of n links, n chains meeting at one pin.

The cost-per-tick study of ``vjm bench`` (:mod:`vjm_ros.studies.bench.scaling`) times them
against their size, and ``vjm_ros.app.precompile`` compiles the hub solves with a star.
"""

from __future__ import annotations

import math

from vjm_ros.scene.loader import Scene, parse_scene

GAINS = "closure_method: {method: penalty, omega_n: 100.0, zeta: 1.0}"
"""The generated scenes' ``closure_method`` line."""


def chain_scene(n_links: int) -> Scene:
    """One chain of ``n_links`` revolute links (1 m, 1 kg in all) whose tip runs on a horizontal line.

    The links hang in a zigzag (absolute angles alternating -60 and -120 degrees); the line passes
    through the initial tip, so the scene closes exactly at t = 0 (one slider row).

    Parameters
    ----------
    n_links : int
        1 or more.

    Returns
    -------
    Scene
    """
    if n_links < 1:
        raise ValueError("n_links: expected 1 or more")
    length, mass = 1.0 / n_links, 1.0 / n_links
    inertia = mass * length**2 / 12.0
    links, x, y = [], 0.0, 0.0
    for k in range(n_links):
        ang = -math.pi / 3 if k % 2 == 0 else -2 * math.pi / 3
        x += length * math.cos(ang)
        y += length * math.sin(ang)
        links.append(
            f"      - {{name: l{k}, length: {length!r}, mass: {mass!r}, inertia: {inertia!r}, "
            f"com: [{length / 2!r}, 0.0], joint: {{name: j{k}, type: revolute, angle: {ang!r}}}}}"
        )
    text = "\n".join([
        f"name: chain_{n_links}",
        "description: generated chain for the cost-per-tick study",
        "chains:",
        "  - name: chain",
        "    links:",
        *links,
        "closures:",
        f"  - {{name: tip_line, type: slider, point: {{link: l{n_links - 1}, at: tip}}, "
        f"line: {{ground: [{x!r}, {y!r}], direction: [1.0, 0.0]}}}}",
        GAINS,
    ])
    return parse_scene(text, source=f"<chain_scene {n_links}>")


def star_scene(n_chains: int) -> Scene:
    """``n_chains`` two-link chains from a unit circle whose tips meet at its centre.

    The first chain's tip is pinned to every other chain's tip (``n_chains - 1`` hinges, two rows
    each); the mechanism keeps two degrees of freedom. Links 0.6 m, 0.5 kg, ``I = m a^2 / 12``.
    ``n_chains``: 1 or more.
    """
    if n_chains < 1:
        raise ValueError("n_chains: expected 1 or more")
    a, m = 0.6, 0.5
    inertia = m * a * a / 12.0
    h = math.sqrt(a * a - 0.25)
    chains = []
    for c in range(n_chains):
        alpha = 2 * math.pi * c / n_chains + 0.1
        bx, by = math.cos(alpha), math.sin(alpha)
        ex, ey = 0.5 * bx - h * by, 0.5 * by + h * bx  # elbow: midpoint plus h along n(alpha)
        th2 = math.atan2(ey - by, ex - bx)
        th3 = math.atan2(-ey, -ex)
        chains += [
            f"  - name: c{c}",
            f"    origin: [{bx!r}, {by!r}]",
            "    links:",
            f"      - {{name: c{c}_p, length: {a!r}, mass: {m!r}, inertia: {inertia!r}, "
            f"com: [{a / 2!r}, 0.0], joint: {{name: c{c}_base, type: revolute, angle: {th2!r}}}}}",
            f"      - {{name: c{c}_d, length: {a!r}, mass: {m!r}, inertia: {inertia!r}, "
            f"com: [{a / 2!r}, 0.0], joint: {{name: c{c}_elbow, type: revolute, angle: {th3!r}}}}}",
        ]
    closures = [
        f"  - {{name: pin{c}, type: hinge, point: {{link: c0_d, at: tip}}, target: {{link: c{c}_d, at: tip}}}}"
        for c in range(1, n_chains)
    ]
    text = "\n".join([
        f"name: star_{n_chains}",
        "description: generated chains meeting at one pin, for the cost-per-tick study",
        "chains:",
        *chains,
        "closures:" + ("" if closures else " []"),
        *closures,
        GAINS,
        "assemble: {fixed: [c0_base]}",
    ])
    return parse_scene(text, source=f"<star_scene {n_chains}>")
