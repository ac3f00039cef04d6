"""PyYAML's safe loader with the limits a scene file needs, and YAML errors as scene errors."""

from __future__ import annotations

import re
from typing import IO

import yaml
from yaml.error import Mark
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from vjm_ros.core.errors import SceneError
from vjm_ros.scene.limits import FILE_KEY, MAX_MERGED_ENTRIES, MAX_NESTING

_MERGE_TAG = "tag:yaml.org,2002:merge"


class _Refused(yaml.MarkedYAMLError):
    """A document the loader refuses, located by a YAML mark and worded as a :class:`SceneError`."""

    def __init__(self, mark, expected: str, found: object):
        super().__init__(problem=f"expected {expected}, found {found!r}", problem_mark=mark)
        self.expected = expected
        self.found = found


class SceneLoader(yaml.SafeLoader):
    """PyYAML's safe loader with the limits a scene file needs.

    * ``1e5`` and ``1.0e5`` are floats (YAML 1.2), as users write them;
    * a key given twice in one mapping is refused (plain PyYAML keeps the last one silently);
    * nesting deeper than :data:`MAX_NESTING` and merge keys that copy more than
      :data:`MAX_MERGED_ENTRIES` entries (a "merge bomb") are refused;
    * a malformed explicitly tagged or implicit scalar (``!!int x``, ``2020-02-30``) is refused
      with its line instead of raising a bare ``ValueError`` from deep inside PyYAML.

    Aliases stay shared references, so a "billion laughs" document costs no memory here; the
    scene builder never walks a value it does not expect, and prints found values through a
    bounded ``repr``.
    """

    def __init__(self, stream: str | bytes | IO[str] | IO[bytes]):
        super().__init__(stream)
        self._depth = 0
        self._merged = 0
        self._flattened: set[int] = set()

    def compose_node(self, parent: Node | None, index: Node | int | None) -> Node:
        """Compose one node, counting the nesting depth."""
        if self._depth >= MAX_NESTING:
            raise _Refused(
                self.peek_event().start_mark,
                f"at most {MAX_NESTING} levels of nesting",
                "deeper nesting",
            )
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def compose_mapping_node(self, anchor: str | None) -> MappingNode:
        """Compose a mapping and refuse a key written twice in it."""
        node = super().compose_mapping_node(anchor)
        seen = set()
        for key_node, _ in node.value:
            if isinstance(key_node, ScalarNode) and key_node.tag != _MERGE_TAG:
                ident = (key_node.tag, key_node.value)
                if ident in seen:
                    raise _Refused(
                        key_node.start_mark, "each key once in a mapping",
                        f"{key_node.value!r} a second time",
                    )
                seen.add(ident)
        return node

    def flatten_mapping(self, node: MappingNode) -> None:
        """Expand merge keys (``<<``) once per mapping, within :data:`MAX_MERGED_ENTRIES` in all.

        The expansion is ours, not PyYAML's, so a scene means the same under every PyYAML 6.x
        (6.0.4 changed how its own expansion treats repeated keys). Semantics of the YAML merge
        key: keys written in the mapping win over merged ones; of several merged mappings the
        first listed wins; a key arrives once however many merged mappings carry it, so mappings
        merged into each other level after level grow linearly, not exponentially. Every merged
        entry looked at counts towards the limit, so a document cannot make the loader do more
        than :data:`MAX_MERGED_ENTRIES` steps of merging.
        """
        if id(node) in self._flattened:
            return
        self._flattened.add(id(node))
        own, sources = [], []
        for key_node, value_node in node.value:
            if key_node.tag != _MERGE_TAG:
                if key_node.tag == "tag:yaml.org,2002:value":
                    key_node.tag = "tag:yaml.org,2002:str"
                own.append((key_node, value_node))
                continue
            subs = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
            for sub in subs:
                if not isinstance(sub, MappingNode):
                    raise _Refused(
                        sub.start_mark, "a mapping or a list of mappings after '<<'", sub.id
                    )
                sources.append((key_node, sub))
        if not sources:
            return
        seen = {_key_identity(k) for k, _ in own}
        merged = []
        for key_node, sub in sources:
            self.flatten_mapping(sub)
            self._merged += len(sub.value)
            if self._merged > MAX_MERGED_ENTRIES:
                raise _Refused(
                    key_node.start_mark,
                    f"merge keys ('<<') that copy at most {MAX_MERGED_ENTRIES} entries in all",
                    f"{self._merged} entries",
                )
            for pair in sub.value:
                ident = _key_identity(pair[0])
                if ident not in seen:
                    seen.add(ident)
                    merged.append(pair)
        node.value = merged + own

    def construct_object(self, node: Node, deep: bool = False) -> object:
        """Construct a value; PyYAML's own errors on malformed scalars become YAML errors."""
        try:
            return super().construct_object(node, deep=deep)
        except yaml.YAMLError:
            raise
        except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError):
            tag = node.tag.replace("tag:yaml.org,2002:", "!!")
            found = node.value if isinstance(node, ScalarNode) else type(node).__name__
            raise _Refused(node.start_mark, f"a valid {tag} value", found) from None


def _key_identity(key_node) -> tuple:
    """What makes two mapping keys the same key: tag and text for scalars, identity otherwise."""
    if isinstance(key_node, ScalarNode):
        return (key_node.tag, key_node.value)
    return ("node", id(key_node))


SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+][0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)



def where(mark: Mark | None) -> str:
    """``line L, column C`` of a YAML mark."""
    if mark is None:
        return FILE_KEY
    return f"line {mark.line + 1}, column {mark.column + 1}"



def parse_yaml(text: str, source: str) -> object:
    """The YAML document in ``text``, read by :class:`SceneLoader` within the limits.

    ``text`` and ``source`` as in :func:`~vjm_ros.scene.loader.parse_scene`. Returns the
    document (a mapping for any scene; the builder checks that).

    Raises
    ------
    SceneError
        Located by line and column, or :data:`~vjm_ros.scene.limits.FILE_KEY`.
    """
    try:
        doc = yaml.load(text, Loader=SceneLoader)  # noqa: S506 (safe loader subclass)
    except _Refused as exc:
        raise SceneError(source, where(exc.problem_mark), exc.expected, exc.found) from None
    except yaml.MarkedYAMLError as exc:
        problem = f"{exc.context}: {exc.problem}" if exc.context else exc.problem
        raise SceneError(source, where(exc.problem_mark), "valid YAML", problem) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise SceneError(
            source, f"line {line}, column {column}", "printable characters",
            f"character U+{exc.character:04X}" if isinstance(exc.character, int) else exc.reason,
        ) from None
    except yaml.YAMLError as exc:
        raise SceneError(source, FILE_KEY, "valid YAML", str(exc)) from None
    except RecursionError:
        raise SceneError(source, FILE_KEY, "a YAML document of reasonable nesting depth",
                         "too deep") from None
    return doc
