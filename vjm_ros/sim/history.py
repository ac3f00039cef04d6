"""The last states before the latest ticks, kept for the diagnosis of a divergence."""

from __future__ import annotations

import collections
from collections.abc import Iterator

import numpy as np


class StateHistory:
    """The last ``maxlen`` states ``(t, q, qd)`` a tick started from, oldest first.

    A tick run alone adds its start state (:meth:`append`); a block of ticks adds its rows in one
    part (:meth:`extend`), copied once, so that a block costs two array copies instead of two per
    tick. States are expanded only when read, which happens when a run diverges.

    Parameters
    ----------
    maxlen : int
        States kept, at least 1.
    """

    def __init__(self, maxlen: int = 32) -> None:
        if maxlen < 1:
            raise ValueError(f"maxlen: expected at least 1, found {maxlen}")
        self.maxlen = maxlen
        self._parts: collections.deque = collections.deque()
        self._count = 0

    def append(self, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        """Add one state (``t`` in s; ``q`` and ``qd``, shape (n,), kept by reference: the caller
        never changes them in place)."""
        self._parts.append((t, None, q, qd))
        self._count += 1
        self._trim()

    def extend(self, tick: int, dt: float, qs: np.ndarray, qds: np.ndarray) -> None:
        """Add the states ``((tick + i) dt, qs[i], qds[i])`` for each row ``i`` (``dt`` in s;
        shape (rows, n), kept by reference: pass copies of rows that will be overwritten)."""
        rows = len(qs)
        if rows == 0:
            return
        self._parts.append((tick, dt, qs, qds))
        self._count += rows
        self._trim()

    def add_block(self, tick: int, dt: float, q: np.ndarray, qd: np.ndarray, qs: np.ndarray,
                  qds: np.ndarray) -> None:
        """Add the states ticks ``tick .. tick + rows - 1`` of a block started from: ``(q, qd)``,
        then the end state of every tick but the last (``qs[i]``, ``qds[i]``, shape (rows, n)).
        Only the rows still among the last ``maxlen`` states are copied (blocks are refilled);
        ``q`` and ``qd`` are kept by reference."""
        rows = len(qs)
        if rows == 0:
            return
        self.append(tick * dt, q, qd)  # dropped again below when the block's rows fill maxlen
        kept = min(rows - 1, self.maxlen)  # end states that start a later tick, kept
        if kept:
            at = slice(rows - 1 - kept, rows - 1)
            self.extend(tick + rows - kept, dt, qs[at].copy(), qds[at].copy())

    def _trim(self) -> None:
        """Drop whole parts that are no longer among the last ``maxlen`` states."""
        while self._parts and self._count - _rows(self._parts[0]) >= self.maxlen:
            self._count -= _rows(self._parts.popleft())

    def __len__(self) -> int:
        return min(self._count, self.maxlen)

    def __iter__(self) -> Iterator[tuple[float, np.ndarray, np.ndarray]]:
        states = []
        for start, dt, q, qd in self._parts:
            if dt is None:
                states.append((start, q, qd))
            else:
                states.extend(((start + i) * dt, q[i], qd[i]) for i in range(len(q)))
        return iter(states[-self.maxlen:])

    def __getitem__(self, index: int) -> tuple[float, np.ndarray, np.ndarray]:
        return list(self)[index]


def _rows(part: tuple) -> int:
    return 1 if part[1] is None else len(part[2])
