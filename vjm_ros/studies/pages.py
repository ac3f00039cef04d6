"""Sections of the Markdown pages the studies write into (``docs/accuracy.md``).

The bench writes most of that page; other studies (the log cost, the start time, the live node)
each own one ``## `` section of it, which the others keep when they rewrite the page.
"""

from __future__ import annotations


def sections(text: str) -> dict[str, str]:
    """The ``## `` sections of a Markdown page by heading, each with its heading line."""
    found: dict[str, str] = {}
    head, body = None, []
    for line in text.splitlines(keepends=True):
        if line.startswith("## "):
            if head is not None:
                found[head] = "".join(body)
            head, body = line[3:].strip(), [line]
        elif head is not None:
            body.append(line)
    if head is not None:
        found[head] = "".join(body)
    return found


def section(text: str, heading: str) -> str | None:
    """The section of a Markdown page whose line is ``heading`` (``## ...``), up to the next
    ``## `` heading (without it); None when the page has none."""
    return sections(text).get(heading[3:].strip())


def with_section(text: str, heading: str, body: str) -> str:
    """``text`` with its ``heading`` section replaced by ``body`` (appended when absent)."""
    old = section(text, heading)
    body = body.rstrip("\n") + "\n"
    if old is None:
        return (text.rstrip("\n") + "\n\n" if text.strip() else "") + body
    tail = "\n" if text.index(old) + len(old) < len(text) else ""
    return text.replace(old, body + tail, 1)
