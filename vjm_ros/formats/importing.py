"""Models of other formats as scenes: the reader chosen by the file's extension.

:func:`import_model` gives the scene document, its YAML text (what ``vjm import`` writes) and
the :class:`~vjm_ros.scene.builder.Scene` built from it (what :func:`vjm_ros.scene.load_scene`
returns for a ``.sdf``, ``.urdf`` or ``.xml`` path).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.joint_graph import reduce_graph
from vjm_ros.scene.builder import Scene, SceneBuilder
from vjm_ros.scene.limits import FILE_KEY


@dataclass(frozen=True)
class ImportedModel:
    """A model read from another format.

    Attributes
    ----------
    document : dict
        The scene document (``docs/design.md`` section 4).
    text : str
        The document as scene YAML.
    ignored : list of str
        What the file holds that the scene does not represent.
    scene : Scene
        The scene built from the document.
    """

    document: dict
    text: str
    ignored: list
    scene: Scene


def _reader(path: str):
    suffix = Path(path).suffix.lower()
    if suffix == ".sdf":
        from vjm_ros.formats.sdformat import read_sdformat

        return read_sdformat
    if suffix == ".urdf":
        from vjm_ros.formats.urdf_in import read_urdf

        return read_urdf
    if suffix == ".xml":
        from vjm_ros.formats.mjcf_in import read_mjcf

        return read_mjcf
    raise SceneError(path, FILE_KEY, "a .sdf, .urdf or MJCF .xml file", suffix or "no extension")


def import_model(path: str | Path, actuate: tuple[str, ...] = ()) -> ImportedModel:
    """Read ``path`` (by its extension) and reduce it to a planar scene.

    Parameters
    ----------
    path : str or Path
        A ``.sdf``, ``.urdf`` or MJCF ``.xml`` file.
    actuate : tuple of str
        Joints to add actuators to (unlimited effort).

    Returns
    -------
    ImportedModel

    Raises
    ------
    SceneError
        Naming the file and the element that cannot be represented (or the line and column of
        malformed XML).
    """
    path = str(path)
    if not Path(path).is_file():
        raise SceneError(path, FILE_KEY, "a readable model file", "no such file")
    graph = _reader(path)(path)
    doc = reduce_graph(graph, tuple(actuate))
    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    scene = _build(path, doc, text)
    if scene is None:  # the file's pose does not close within the tolerance: assemble it
        doc["assemble"] = {"fixed": []}
        doc["provenance"] += ("\nThe file's pose does not close the loops within the scene "
                              "tolerance: the start is assembled.")
        text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
        scene = SceneBuilder(path, text).build(doc)
    return ImportedModel(doc, text, list(dict.fromkeys(graph.ignored)), scene)


def _build(path: str, doc: dict, text: str) -> Scene | None:
    """The scene, or None when only the closures at t = 0 fail (assembly needed)."""
    try:
        return SceneBuilder(path, text).build(doc)
    except SceneError as exc:
        if exc.key.startswith("closures[") and "hold at t = 0" in exc.expected:
            return None
        raise
