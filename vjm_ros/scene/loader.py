"""Scene files: YAML to :class:`~vjm_ros.core.model.Model` plus run defaults.

This is the one place that reports schema errors; each names the file, the key path, what was
expected and what was found (:class:`~vjm_ros.core.errors.SceneError`). The built-in scenes under
``vjm_ros/scene/builtin/`` are complete examples of the format; ``docs/troubleshooting.md`` lists the
errors.

Key paths are written ``chains[0].links[1].mass``. Errors that no key can locate use a line and
column (``line 3, column 7``: YAML syntax, bytes that are not UTF-8), ``FILE_KEY`` (the file
cannot be read) or ``TOP_KEY`` (the document is not a mapping).

Loading is bounded (:mod:`vjm_ros.scene.limits`): a file holds at most ``MAX_SCENE_BYTES``,
nesting at most ``MAX_NESTING`` levels, YAML merge keys expand to at most ``MAX_MERGED_ENTRIES``
entries, and a scene has at most ``MAX_LINKS`` links and ``MAX_CLOSURES`` closures, so that any
file, however malformed, is accepted or refused within a fraction of a second.
"""

from __future__ import annotations

from importlib import import_module, resources
from pathlib import Path

from vjm_ros.core.errors import SceneError
from vjm_ros.scene.builder import Scene, SceneBuilder
from vjm_ros.scene.limits import FILE_KEY, MAX_SCENE_BYTES
from vjm_ros.scene.safe_yaml import parse_yaml

__all__ = ["Scene", "builtin_scene_text", "builtin_scenes", "load_scene", "parse_scene"]


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with the package."""
    root = resources.files("vjm_ros.scene") / "builtin"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".yaml"))


def builtin_scene_text(name: str) -> str:
    """YAML text of a built-in scene."""
    return (resources.files("vjm_ros.scene") / "builtin" / f"{name}.yaml").read_text(encoding="utf-8")


MODEL_SUFFIXES = (".sdf", ".urdf", ".xml")
"""Extensions of model files of other formats (SDFormat, URDF, MJCF), read as scenes by
:data:`MODEL_READER`."""
MODEL_READER = "vjm_ros.formats.importing"
"""The module whose ``import_model(path).scene`` reads them. ``vjm_ros.formats`` sits above this
layer (it builds scene documents with it), so it is found by name when a model path is loaded."""


def load_scene(spec: str | Path) -> Scene:
    """Load a built-in scene by name, a YAML file by path, or a model of another format.

    Parameters
    ----------
    spec : str or Path
        A name from :func:`builtin_scenes`, the path of a UTF-8 YAML file of at most
        ``MAX_SCENE_BYTES`` bytes, or the path of a ``.sdf``, ``.urdf`` or MJCF ``.xml``
        model (docs/models.md).

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        With file, key path, expected and found value.
    """
    spec_s = str(spec)
    if spec_s in builtin_scenes():
        return parse_scene(builtin_scene_text(spec_s), source=f"<builtin {spec_s}>")
    if spec_s.lower().endswith(MODEL_SUFFIXES):
        return import_module(MODEL_READER).import_model(spec_s).scene
    return parse_scene(_read_file(spec_s), source=spec_s)


def _read_file(spec: str) -> str:
    """Text of a scene file, newlines normalized as :meth:`Path.read_text` does."""
    path = Path(spec)
    try:
        exists, regular = path.exists(), path.is_file()
        if regular:
            with path.open("rb") as fh:
                raw = fh.read(MAX_SCENE_BYTES + 1)
    except (OSError, ValueError) as exc:  # name too long, embedded NUL, permission denied, ...
        reason = getattr(exc, "strerror", None) or str(exc)
        raise SceneError(spec, FILE_KEY, "a readable file", reason) from None
    if not exists:
        raise SceneError(
            spec, FILE_KEY,
            f"a built-in scene name ({', '.join(builtin_scenes())}) or a YAML file path",
            "no such scene or file",
        )
    if not regular:
        raise SceneError(spec, FILE_KEY, "a regular file", "a directory or device")
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(
            spec, FILE_KEY, f"a file of at most {MAX_SCENE_BYTES} bytes",
            f"more than {MAX_SCENE_BYTES} bytes",
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        start = raw.rfind(b"\n", 0, exc.start) + 1
        column = len(raw[start : exc.start].decode("utf-8", "replace")) + 1
        raise SceneError(
            spec, f"line {line}, column {column}", "UTF-8 text", f"byte 0x{raw[exc.start]:02x}"
        ) from None
    return text.replace("\r\n", "\n").replace("\r", "\n")


def parse_scene(text: str, source: str = "<string>") -> Scene:
    """Parse and validate scene YAML ``text``; ``source`` names it in error messages.

    Returns the :class:`Scene`; raises :class:`~vjm_ros.core.errors.SceneError` as
    :func:`load_scene` does.
    """
    if not isinstance(text, str):
        raise SceneError(source, FILE_KEY, "scene text (str)", type(text).__name__)
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(
            source, FILE_KEY, f"at most {MAX_SCENE_BYTES} characters", f"{len(text)} characters"
        )
    return SceneBuilder(source, text).build(parse_yaml(text, source))
