"""Scenes: YAML files to models (validation, built-in scenes, assembly). Imports only ``core``.

The names most users need are here: :func:`load_scene` (a built-in name or a file),
:func:`parse_scene` (YAML text, e.g. what the node publishes), :func:`builtin_scenes`, :class:`Scene`.
"""

from vjm_ros.scene.loader import Scene, builtin_scenes, load_scene, parse_scene

__all__ = ["Scene", "builtin_scenes", "load_scene", "parse_scene"]
