"""The fenced code blocks of the docs, and how the commands they hold are run.

Helpers of ``test/test_docs.py`` (which states the convention): reading the blocks, splitting a
``bash`` block into commands, running a command in its own process group with a hang guard, and
reading the paths of a map and the options of a usage synopsis.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VENV_BIN = ROOT / ".venv" / "bin"
DOC_FILES = ["README.md", "CONTRIBUTING.md",
             *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md"))]
DOMAIN = os.environ["ROS_DOMAIN_ID"]  # this test process's own (conftest.py)
HANG_GUARD = 120.0
"""Wall seconds a documented command may take before it counts as hung (not a speed limit)."""
SETUP_GUARD = 3600.0
"""The same for a set-up from nothing, which downloads and compiles (minutes)."""

FENCE = re.compile(r"^(?P<indent> *)(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")


# ------------------------------------------------------------------------------------- blocks
@dataclass(frozen=True)
class Block:
    """One fenced code block: its file, the line of its opening fence (from 1), info and text."""

    path: str
    line: int
    info: str
    text: str

    @property
    def id(self) -> str:
        return f"{self.path}:{self.line}"

    @property
    def kind(self) -> str:
        """The handled kind its info string names, or ``'unhandled'``."""
        words = self.info.split()
        lang, rest = (words[0], words[1:]) if words else ("", [])
        if lang in ("python", "bash", "console") and not rest:
            return lang
        if lang == "yaml" and rest in (["scene"], ["sweep-spec"]):
            return f"yaml {rest[0]}"
        if lang == "text" and rest == ["paths"]:
            return "text paths"
        if lang == "text" and len(rest) == 1 and rest[0].startswith("check:"):
            return "text check"
        return "unhandled"

    def preceding_text(self) -> str:
        """The doc's text above the block, back to the previous fence or heading."""
        lines = (ROOT / self.path).read_text(encoding="utf-8").splitlines()[: self.line - 1]
        out: list[str] = []
        for line in reversed(lines):
            if line.lstrip().startswith(("```", "~~~", "#")):
                break
            out.append(line)
        return "\n".join(reversed(out))


def doc_blocks() -> list[Block]:
    """Every fenced block of the docs, in file order (CommonMark fences, indented ones too)."""
    blocks = []
    for name in DOC_FILES:
        lines = (ROOT / name).read_text(encoding="utf-8").splitlines()
        i = 0
        while i < len(lines):
            match = FENCE.match(lines[i])
            if not match:
                i += 1
                continue
            indent, fence = len(match["indent"]), match["fence"]
            body, j = [], i + 1
            while j < len(lines):
                close = lines[j].strip()
                if close and set(close) == {fence[0]} and len(close) >= len(fence):
                    break
                body.append(lines[j][indent:] if not lines[j][:indent].strip() else lines[j])
                j += 1
            else:
                raise AssertionError(f"{name}:{i + 1}: a code fence that is never closed")
            blocks.append(Block(name, i + 1, match["info"].strip(), "\n".join(body) + "\n"))
            i = j + 1
    return blocks


def flat(text: str) -> str:
    """Whitespace-normalized text (a doc wraps long messages over lines)."""
    return " ".join(text.split())


NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def masked(text: str) -> str:
    """``text`` with every number replaced by ``#``."""
    return NUMBER.sub("#", flat(text))


ROS_STAMP = re.compile(r"^\[(\w+)\] \[\d+\.\d+\] ")


def without_stamp(line: str) -> str:
    """A ROS 2 console line without its wall-clock stamp field, which the docs leave out."""
    return ROS_STAMP.sub(r"[\1] ", line.strip())


# ------------------------------------------------------------------------ running commands
def command_env(where: str, exports: dict[str, str] | None = None) -> dict[str, str]:
    """The environment a documented command runs in (see the module documentation)."""
    env = dict(os.environ)
    env.pop("VJM_TIERED", None)  # as the docs' readers run it (the suite itself compiles first)
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=DOMAIN)
    if where != "clone":  # a fresh clone uses its own .venv, by relative paths
        env["PATH"] = f"{VENV_BIN}{os.pathsep}{env['PATH']}"
    env.update(exports or {})
    return env


def start(command: str, cwd: Path, env: dict) -> subprocess.Popen:
    """``bash -c command`` in a process group of its own (so that all of it can be stopped)."""
    return subprocess.Popen(["bash", "-c", command], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)


def stop(proc: subprocess.Popen, sig: int = signal.SIGINT) -> None:
    """Signal the process group ``start`` made (only processes this test started)."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass


def finish(proc: subprocess.Popen, timeout: float, what: str) -> str:
    """Wait for ``proc`` (``timeout``: a hang guard) and return its output."""
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        stop(proc, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"hang guard: {what} still running after {timeout:g} s; output:\n{out}")
    return out


def commands(text: str) -> list[str]:
    """The commands of a ``bash`` block: comment and blank lines dropped, ``\\`` continuations
    and quoted newlines kept inside their command."""
    out, pending = [], ""
    for line in text.splitlines():
        if not pending and (not line.strip() or line.lstrip().startswith("#")):
            continue
        pending = f"{pending}\n{line}" if pending else line
        if pending.endswith("\\"):
            continue
        try:
            shlex.split(pending, comments=True)
        except ValueError:  # an open quote: the command goes on on the next line
            continue
        out.append(pending)
        pending = ""
    assert not pending, f"an unfinished command: {pending!r}"
    return out


def console_commands(text: str) -> list[tuple[str, list[str]]]:
    """``(command, output lines)`` of a ``console`` block."""
    out: list[tuple[str, list[str]]] = []
    for line in text.splitlines():
        if line.startswith("$ "):
            out.append((line[2:], []))
        elif line.strip():
            assert out, f"output before the first '$ ' command: {line!r}"
            out[-1][1].append(line)
    return out


def key(command: str) -> str:
    """A command's words without comments: what declarations are looked up by."""
    return " ".join(shlex.split(command.replace("\\\n", " "), comments=True))


def background(command: str) -> bool:
    """Whether ``command`` ends with ``&`` (it runs beside the next one)."""
    return shlex.split(command.replace("\\\n", " "), comments=True)[-1:] == ["&"]


def foreground(command: str) -> str:
    """``command`` without its trailing ``&`` and comment."""
    words = shlex.split(command.replace("\\\n", " "), comments=True)
    return shlex.join(words[:-1] if words[-1:] == ["&"] else words)


# ----------------------------------------------------------------------------- maps
PATH_TOKEN = re.compile(
    r"(?<![\w./-])((?:[\w*-]+/)+(?:[\w*-]+(?:\.\w+)?)?|[\w*-]+\.(?:py|yaml|md|cfg|toml|txt|in))"
    r"(?![\w/-])")


def named_paths(block: Block) -> list[tuple[int, str, list[Path]]]:
    """``(line, path, bases)`` of every path a map names; an indented ``name/`` that starts a
    line is a folder inside the folder above it, and the paths on its lines are relative to it,
    to ``vjm_ros/`` or to the repository."""
    found, stack = [], []  # stack: (indent, folder)
    for n, line in enumerate(block.text.splitlines(), start=block.line + 1):
        stripped = line.lstrip()
        indent = len(line) - len(stripped)
        first = stripped.split(" ", 1)[0]
        if re.fullmatch(r"[\w-]+/", first):
            while stack and stack[-1][0] >= indent:
                stack.pop()
            parent = stack[-1][1] if stack else ROOT
            stack.append((indent, parent / first))
        bases = [ROOT, ROOT / "vjm_ros", *(folder for _, folder in stack)]
        found += [(n, match[1], bases) for match in PATH_TOKEN.finditer(stripped)]
    return found


# ------------------------------------------------------------------------ synopses
USAGE_TOKEN = re.compile(r"\[|\]|\||[^\s\[\]|]+")


def synopsis_options(usage: str) -> dict[str, tuple[bool, bool]]:
    """``option -> (optional, takes a value)`` of a usage synopsis (argparse's or a doc's)."""
    tokens = USAGE_TOKEN.findall(usage)
    depth, options = 0, {}
    for i, tok in enumerate(tokens):
        if tok == "[":
            depth += 1
        elif tok == "]":
            depth -= 1
        elif re.fullmatch(r"--?[A-Za-z][\w-]*", tok):
            nxt = tokens[i + 1] if i + 1 < len(tokens) else "]"
            options[tok] = (depth > 0, nxt not in "[]|" and not nxt.startswith("-"))
    return options

