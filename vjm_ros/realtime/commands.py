"""Effort commands between the ROS callbacks and the tick loop, without ROS.

Rules (docs/design.md section 5 and the node's documentation):

* a command is one value per actuator in the scene's actuator order (``~/effort_commands``), or
  efforts matched by joint name (``~/joint_commands``; actuators not named keep their value);
* a command is refused as a whole, with the reason, when it holds a non-finite value, has the
  wrong length, names an unknown or a non-actuated joint, names a joint twice, or carries no
  efforts; the efforts in force then do not change;
* a command message bigger than the scene can need (:class:`SizeBounds`) is refused before it is
  read, from the counts at the head of its fields (:meth:`CommandBuffer.refuse_oversize`): reading
  one is the tick loop's time;
* values beyond an actuator's limit are clamped to it (and reported);
* the tick loop reads the buffer once at the start of every tick (:meth:`CommandBuffer.latch`):
  a command received while tick ``k`` runs therefore applies from tick ``k + 1`` on;
* the last valid command holds until ``timeout`` seconds pass without a new one, then the efforts
  fall to zero, reported once (until a new command arrives);
* in lockstep mode the loop waits for a command received since the previous tick
  (:meth:`CommandBuffer.wait_fresh`).

Callbacks and the loop run in different threads; every method is thread-safe.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

# classes of refused commands (the keys of the throttled warnings)
NON_FINITE = "non_finite"
WRONG_LENGTH = "wrong_length"
UNKNOWN_JOINT = "unknown_joint"
NOT_ACTUATED = "not_actuated"
DUPLICATE_JOINT = "duplicate_joint"
NO_EFFORTS = "no_efforts"
MALFORMED = "malformed"
OVERSIZE = "oversize"


@dataclass(frozen=True)
class Verdict:
    """What became of one command.

    Attributes
    ----------
    accepted : bool
        The command replaced the efforts in force (possibly clamped).
    kind : str
        Class of the refusal (:data:`NON_FINITE` ... :data:`OVERSIZE`), empty when accepted.
    reason : str
        Why it was refused, in words that name the offending entries.
    clamped : tuple of str
        One description per value clamped to its actuator's limit.
    """

    accepted: bool
    kind: str = ""
    reason: str = ""
    clamped: tuple[str, ...] = ()


_ACCEPTED = Verdict(True)
"""The verdict of every command accepted as it is (immutable, so shared)."""


@dataclass(frozen=True)
class Latched:
    """The efforts for one tick.

    Attributes
    ----------
    efforts : ndarray, shape (n_actuators,)
        N m or N, scene actuator order, within the limits.
    fresh : bool
        A valid command arrived since the previous latch.
    timed_out : bool
        The command in force expired at this latch (efforts fell to zero); true once per expiry.
    """

    efforts: np.ndarray
    fresh: bool
    timed_out: bool


SIZE_SLACK = 32
"""Entries a command may hold beyond the scene's joints before it is refused unread: a command
a little too long still gets the reason that names its entries (wrong length, unknown or
non-actuated joint, duplicate)."""
MAX_LAYOUT_DIMS = 8
"""Most layout dimensions of an effort command read (one describes a vector of efforts;
ros2_control's forward command controllers send none)."""
MAX_TEXT_BYTES = 256
"""Longest layout label, and shortest longest joint name, read, in UTF-8 bytes."""


@dataclass(frozen=True)
class SizeBounds:
    """The largest command messages a scene can need; bigger ones are refused before reading.

    A valid command holds one effort per actuator (``~/effort_commands``), or at most one name
    and effort per actuated joint (``~/joint_commands``), so nothing near these bounds can be
    valid. The decoder compares the element counts at the head of each field with them before
    any per-element work (``ros/command_wire.py``).

    Attributes
    ----------
    values : int
        Most values of ``data`` (``Float64MultiArray``) or ``effort`` (``JointState``).
    names : int
        Most entries of ``name`` (``JointState``).
    name_bytes : int
        Longest name, UTF-8 bytes.
    dims : int
        Most entries of ``layout.dim`` (``Float64MultiArray``).
    label_bytes : int
        Longest ``layout.dim.label``, UTF-8 bytes.
    """

    values: int
    names: int
    name_bytes: int
    dims: int = MAX_LAYOUT_DIMS
    label_bytes: int = MAX_TEXT_BYTES

    @classmethod
    def for_scene(cls, actuator_names: Sequence[str], joint_names: Sequence[str]) -> SizeBounds:
        """Bounds for a scene: its joints plus :data:`SIZE_SLACK` entries, names no longer than
        its longest joint name or :data:`MAX_TEXT_BYTES`."""
        count = max(len(actuator_names), len(joint_names)) + SIZE_SLACK
        longest = max((len(n.encode("utf-8")) for n in joint_names), default=0)
        return cls(values=count, names=count, name_bytes=max(longest, MAX_TEXT_BYTES))


LISTED = 8
"""Most entries a refusal lists (a flood of junk names must not become a flood of text)."""


def _names(items: Sequence[str]) -> str:
    shown = ", ".join(f"'{s[:64]}'" for s in items[:LISTED])
    more = len(items) - LISTED
    return f"{shown} and {more} more" if more > 0 else shown


class CommandBuffer:
    """Validated, clamped, timed-out efforts shared by the subscriptions and the tick loop.

    Parameters
    ----------
    actuator_names : sequence of str
        Actuated joints in the scene's actuator order.
    joint_names : sequence of str
        Every joint of the scene (to tell unknown names from non-actuated ones).
    limits : array_like, shape (n_actuators,)
        Largest admissible ``|effort|`` per actuator, N m or N.
    timeout : float
        Seconds (of ``clock``) a command holds without a new one; 0 holds forever.
    clock : callable
        Monotonic time in seconds (``time.monotonic`` by default; tests pass a fake one).
    """

    def __init__(
        self,
        actuator_names: Sequence[str],
        joint_names: Sequence[str],
        limits: np.ndarray | Sequence[float],
        timeout: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.actuator_names = list(actuator_names)
        self.joint_names = list(joint_names)
        self.limits = np.asarray(limits, dtype=float).reshape(-1)
        if self.limits.shape != (len(self.actuator_names),):
            raise ValueError("one limit per actuator is required")
        self._limit_list = self.limits.tolist()
        self._index = {name: i for i, name in enumerate(self.actuator_names)}
        self._joints = set(self.joint_names)
        self.timeout = float(timeout)
        self._clock = clock
        self._cv = threading.Condition()
        self._efforts = np.zeros(len(self.actuator_names))
        self._stamp = 0.0
        self._active = False
        self._fresh = False
        self._unchanged: Latched | None = None
        self.size_bounds = SizeBounds.for_scene(self.actuator_names, self.joint_names)
        """The largest command messages worth reading for this scene."""
        self.accepted = 0
        self.rejected = 0
        self.oversize = 0
        """Commands refused for their size, unread (also counted in :attr:`rejected`)."""
        self.clamped = 0
        self.timeouts = 0

    # ------------------------------------------------------------------ producers
    def submit_array(self, values: Sequence[float] | np.ndarray) -> Verdict:
        """Offer one value per actuator, scene actuator order (``~/effort_commands``).

        Parameters
        ----------
        values : array_like, shape (n_actuators,)
            N m or N.

        Returns
        -------
        Verdict
        """
        # Python floats: at 1 kHz this runs every tick, and numpy's per-call overhead on a few
        # entries is several times the work
        v = np.asarray(values, dtype=float).reshape(-1).tolist()
        n = len(self.actuator_names)
        if len(v) != n:
            return self._reject(
                WRONG_LENGTH,
                f"expected {n} value{'s' if n != 1 else ''} (actuators in scene order: "
                f"{_names(self.actuator_names)}), found {len(v)}",
            )
        bad = [i for i in range(n) if not math.isfinite(v[i])]
        if bad:
            what = ", ".join(f"{self.actuator_names[i]} = {v[i]}" for i in bad)
            return self._reject(NON_FINITE, f"non-finite effort ({what})")
        return self._accept(v, range(n))

    def submit_named(self, names: Sequence[str], efforts: Sequence[float] | np.ndarray) -> Verdict:
        """Offer efforts by joint name (``~/joint_commands``); unnamed actuators keep their value.

        Parameters
        ----------
        names : sequence of str
            Actuated joint names.
        efforts : array_like, shape (len(names),)
            N m or N.

        Returns
        -------
        Verdict
        """
        names = list(names)
        e = np.asarray(efforts, dtype=float).reshape(-1)
        if not names or e.size == 0:
            return self._reject(
                NO_EFFORTS,
                f"expected joint names with efforts, found {len(names)} name(s) and "
                f"{e.size} effort(s)",
            )
        if len(names) != e.size:
            return self._reject(
                WRONG_LENGTH, f"'name' has {len(names)} entries but 'effort' has {e.size}"
            )
        if len(set(names)) != len(names):
            dup = sorted(s for s, count in Counter(names).items() if count > 1)
            return self._reject(DUPLICATE_JOINT, f"joint named more than once: {_names(dup)}")
        unknown = [s for s in names if s not in self._joints]
        if unknown:
            return self._reject(
                UNKNOWN_JOINT,
                f"unknown joint {_names(unknown)} (joints of the scene: {_names(self.joint_names)})",
            )
        passive = [s for s in names if s not in self._index]
        if passive:
            return self._reject(
                NOT_ACTUATED,
                f"joint {_names(passive)} has no actuator (actuated joints: "
                f"{_names(self.actuator_names)})",
            )
        values = e.tolist()
        bad = [f"{s} = {x}" for s, x in zip(names, values, strict=True) if not math.isfinite(x)]
        if bad:
            return self._reject(NON_FINITE, f"non-finite effort ({', '.join(bad)})")
        with self._cv:
            v = self._efforts.tolist() if self._active else [0.0] * len(self.actuator_names)
        idx = [self._index[s] for s in names]
        for i, x in zip(idx, values, strict=True):
            v[i] = x
        return self._accept(v, idx)

    def refuse_malformed(self, reason: str) -> Verdict:
        """Count a command whose bytes held no readable message (``reason`` says where)."""
        return self._reject(MALFORMED, reason)

    def refuse_oversize(self, reason: str) -> Verdict:
        """Count a command refused unread, bigger than :attr:`size_bounds` (``reason`` says
        which field and how big)."""
        with self._cv:
            self.oversize += 1
        return self._reject(OVERSIZE, reason)

    def _reject(self, kind: str, reason: str) -> Verdict:
        with self._cv:
            self.rejected += 1
        return Verdict(False, kind, reason)

    def _accept(self, v: list[float], touched) -> Verdict:
        """Put the finite efforts ``v`` (one per actuator) in force, each within its limit."""
        clipped = [min(max(x, -lim), lim) for x, lim in zip(v, self._limit_list, strict=True)]
        if clipped == v:
            clamped, verdict = (), _ACCEPTED
        else:
            clamped = tuple(
                f"{self.actuator_names[i]}: {v[i]:.6g} clamped to {clipped[i]:.6g} "
                f"(limit {self.limits[i]:.6g})"
                for i in touched
                if clipped[i] != v[i]
            )
            verdict = Verdict(True, clamped=clamped)
        efforts = np.array(clipped, dtype=float)
        with self._cv:
            self._efforts = efforts
            self._stamp = self._clock()
            self._active = True
            self._fresh = True
            self.accepted += 1
            self.clamped += len(clamped)
            self._cv.notify_all()
        return verdict

    # ------------------------------------------------------------------ consumer
    def latch(self) -> Latched:
        """Efforts for the tick about to start (call once per tick, before stepping).

        Returns
        -------
        Latched
        """
        with self._cv:
            fresh, self._fresh = self._fresh, False
            timed_out = False
            if self._active and self.timeout > 0 and self._clock() - self._stamp > self.timeout:
                self._efforts = np.zeros(len(self.actuator_names))
                self._active = False
                self.timeouts += 1
                timed_out = True
            if fresh or timed_out:
                return Latched(self._efforts.copy(), fresh, timed_out)
            # nothing new (most ticks): the previous such answer, a read-only view (every
            # change replaces self._efforts, none writes into it)
            if self._unchanged is None or self._unchanged.efforts.base is not self._efforts:
                view = self._efforts.view()
                view.flags.writeable = False
                self._unchanged = Latched(view, False, False)
            return self._unchanged

    def wait_fresh(self, timeout: float) -> bool:
        """Block until a valid command arrives that the next latch has not seen yet.

        Parameters
        ----------
        timeout : float
            Longest wait, s.

        Returns
        -------
        bool
            True if such a command is waiting.
        """
        with self._cv:
            return self._cv.wait_for(lambda: self._fresh, timeout=max(timeout, 0.0))

    def clear(self) -> None:
        """Drop the command in force and any unread one (efforts back to zero)."""
        with self._cv:
            self._efforts = np.zeros(len(self.actuator_names))
            self._active = False
            self._fresh = False

    @property
    def efforts(self) -> np.ndarray:
        """The efforts the next latch would return if nothing changes, N m or N."""
        with self._cv:
            return self._efforts.copy()


class Throttle:
    """At most one report per key and period; counts what it held back.

    Parameters
    ----------
    period : float
        Seconds between two reports of one key.
    clock : callable
        Monotonic time in seconds.
    """

    def __init__(self, period: float = 1.0, clock: Callable[[], float] = time.monotonic):
        self.period = float(period)
        self._clock = clock
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}
        self._lock = threading.Lock()

    def __call__(self, key: str) -> int | None:
        """Ask to report ``key`` now.

        Returns
        -------
        int or None
            None when the report must be dropped; otherwise how many reports of this key were
            dropped since the previous one.
        """
        now = self._clock()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self.period:
                self._held[key] = self._held.get(key, 0) + 1
                return None
            self._last[key] = now
            return self._held.pop(key, 0)
