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
    """The section of a Markdown page that starts with the line ``heading``, up to the next
    ``## `` heading (without it); None when the page has none."""
    lines = text.splitlines(keepends=True)
    starts = [i for i, ln in enumerate(lines) if ln.rstrip("\n") == heading]
    if not starts:
        return None
    end = next((i for i in range(starts[0] + 1, len(lines)) if lines[i].startswith("## ")),
               len(lines))
    return "".join(lines[starts[0] : end])


def with_section(text: str, heading: str, body: str) -> str:
    """``text`` with its ``heading`` section replaced by ``body`` (appended when absent)."""
    old = section(text, heading)
    body = body.rstrip("\n") + "\n"
    if old is None:
        return (text.rstrip("\n") + "\n\n" if text.strip() else "") + body
    tail = "\n" if text.index(old) + len(old) < len(text) else ""
    return text.replace(old, body + tail, 1)
