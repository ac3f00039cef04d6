"""A scene as other nodes get it: its YAML with the assembled initial state written out.

The node publishes this text on ``~/scene_description`` (``std_msgs/String``, transient-local, as
robot_state_publisher publishes ``robot_description``): a controller or a tool loads it with
:func:`vjm_ros.scene.parse_scene` and gets the model the simulator runs, in the state it starts
from. The text is the scene file's own document with every joint's ``angle``, ``slide`` and
``velocity`` replaced by the values after assembly (in the file's angle unit), without the
``assemble`` section (the closures hold as written), so it loads to the same model.
"""

from __future__ import annotations

import json
import math

import numpy as np
import yaml

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.core.model import REVOLUTE, Model
from vjm_ros.scene.assembly import assemble
from vjm_ros.scene.builder import Scene
from vjm_ros.scene.safe_yaml import SceneLoader


def assembled_scene_yaml(scene: Scene) -> str:
    """The scene's YAML with the initial state of ``scene.model`` written out.

    Parameters
    ----------
    scene : Scene
        A loaded scene; its model's initial state (possibly re-assembled, see
        :func:`with_initial_positions`) is what the text states.

    Returns
    -------
    str
        YAML that :func:`~vjm_ros.scene.parse_scene` loads to a model with the same links,
        joints, closures and initial state.
    """
    # Plain data (YAML aliases unshared), so that each joint is written on its own.
    doc = json.loads(json.dumps(yaml.load(scene.text, Loader=SceneLoader)))  # noqa: S506
    model = scene.model
    units = doc.get("units") or {}
    scale = 180.0 / math.pi if units.get("angle") == "degrees" else 1.0
    k = 0
    for chain, chain_doc in zip(model.chains, doc["chains"], strict=True):
        theta = chain.angle
        for link_doc in chain_doc["links"]:
            joint, joint_doc = model.joints[k], link_doc["joint"]
            theta += joint.angle
            joint_doc["angle"] = float(theta) * scale
            joint_doc["slide"] = float(joint.slide)
            rate = joint.velocity * (scale if joint.kind == REVOLUTE else 1.0)
            joint_doc["velocity"] = float(rate)
            k += 1
    doc.pop("assemble", None)
    note = "Initial state assembled by vjm_ros (joint angles, slides and rates written out)."
    doc["provenance"] = f"{doc.get('provenance', '')}\n{note}".strip()
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def with_initial_positions(
    model: Model, positions: dict[str, float], name: str = "initial_positions",
) -> Model:
    """The model started from given joint values, the other coordinates assembled.

    Parameters
    ----------
    model : Model
    positions : dict
        Joint name to initial value (rad for revolute joints, m for prismatic ones); these
        joints are held while the others are solved so that the closures hold (to a
        residual of 1e-10 m or rad).
    name : str
        How the positions are named in error messages (the parameter or flag).

    Returns
    -------
    Model

    Raises
    ------
    ConfigurationError
        An unknown joint or a non-finite value (naming it), or positions the closures cannot meet
        (with the residual reached).
    """
    names = model.joint_names
    q, qd = model.initial_state()
    fixed = []
    for joint, value in positions.items():
        if joint not in names:
            raise ConfigurationError(
                f"{name}.{joint}: expected a joint of {model.name} "
                f"({', '.join(names)}), found {joint!r}"
            )
        if not math.isfinite(value):
            raise ConfigurationError(f"{name}.{joint}: expected a finite number, found {value}")
        i = names.index(joint)
        q[i], qd[i] = float(value), 0.0
        fixed.append(i)
    if not fixed:
        return model
    guess = model.with_state(q, np.zeros_like(qd))
    tolerance = 1e-10
    with np.errstate(all="ignore"):
        q_new, qd_new, err = assemble(guess, fixed, tolerance)
    if not err <= tolerance or not np.all(np.isfinite(q_new)):
        given = ", ".join(f"{n} = {v:g}" for n, v in positions.items())
        raise ConfigurationError(
            f"{name}: expected joint values the closures can meet, found {given} "
            f"(closure residual {err:.3g} after assembly, tolerance {tolerance:g})"
        )
    return model.with_state(q_new, qd_new)
