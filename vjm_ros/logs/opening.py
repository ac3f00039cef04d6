"""Opening the logs of a run, the same way for ``vjm run`` and the node."""

from __future__ import annotations

import functools
from collections.abc import Callable

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.core.model import Model
from vjm_ros.logs.storage import check_log_path, is_file_target


def recorder_openers(
    model: Model,
    settings: dict,
    scene_text: str,
    *,
    mcap: str | None = None,
    rrd: str | None = None,
    duration: float = 0.0,
    rate: float = 1000.0,
    keys: tuple[str, str] = ("mcap", "rrd"),
    chunk_seconds: float | None = None,
    total_samples: int | None = None,
) -> list[tuple[str, Callable[[], object]]]:
    """The storage checks of the logs asked for, then one function per log that opens it.

    Parameters
    ----------
    model : Model
    settings : dict
        Run settings written into the logs (``Simulator.describe()`` plus what the caller adds).
    scene_text : str
        The scene YAML, attached to the MCAP log.
    mcap, rrd : str, optional
        Log paths (or ``rerun`` targets such as ``rerun+http://...`` for ``rrd``); None or ""
        for no log.
    duration : float
        Simulated seconds the run will last (0: unknown), for the free-space check, s.
    rate : float
        Control ticks per second, Hz.
    keys : tuple of str
        How the two logs are named in error messages (``("--mcap", "--rrd")`` on the command line).
    chunk_seconds : float, optional
        Length of the MCAP log's chunks, s of simulated or wall time (the recorder's default when
        None; see :class:`~vjm_ros.logs.McapRecorder`).
    total_samples : int, optional
        The samples the run will write, when known, for the rerun log's sends (see
        :class:`~vjm_ros.logs.RerunRecorder`).

    Returns
    -------
    list of (str, callable)
        The option or parameter naming the log (``keys[0]`` for the MCAP, first) and a function
        without arguments that returns the open recorder, or raises :class:`ConfigurationError`
        naming the key when the recorder is not available or the file cannot be opened. The
        functions may run in other threads.

    Raises
    ------
    ConfigurationError
        A path fails the checks of :func:`~vjm_ros.logs.storage.check_log_path`.
    """
    wanted = [(keys[0], mcap, "McapRecorder"), (keys[1], rrd, "RerunRecorder")]
    for key, path, _ in wanted:
        if path and is_file_target(path):
            check_log_path(path, key, duration, rate)
    return [(key, functools.partial(_open, key, path, cls_name, model, settings, scene_text,
                                    chunk_seconds, total_samples))
            for key, path, cls_name in wanted if path]


def _open(key: str, path, cls_name: str, model: Model, settings: dict, scene_text: str,
          chunk_seconds: float | None = None, total_samples: int | None = None):
    """One recorder, opened; a :class:`ConfigurationError` naming ``key`` if it cannot be."""
    try:
        from vjm_ros import logs

        cls = getattr(logs, cls_name)
    except (ImportError, AttributeError) as exc:
        raise ConfigurationError(f"{key}: {cls_name} is not available ({exc})") from None
    if cls_name == "McapRecorder":
        args, options = (path, model, settings, scene_text), {"chunk_seconds": chunk_seconds}
    else:
        args, options = (path, model, settings), {"total_samples": total_samples}
    options = {k: v for k, v in options.items() if v is not None}  # None: the default
    try:
        return cls(*args, **options)
    except (OSError, RuntimeError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or exc
        raise ConfigurationError(f"{key}: cannot open {path!r} ({reason})") from None


def open_recorders(model: Model, settings: dict, scene_text: str, **options) -> list:
    """The MCAP and rerun recorders asked for, after the storage checks.

    Parameters
    ----------
    model, settings, scene_text, **options
        As for :func:`recorder_openers` (``options``: ``mcap``, ``rrd``, ``duration``, ``rate``,
        ``keys``).

    Returns
    -------
    list
        The open recorders (MCAP first); none is left open when this raises.

    Raises
    ------
    ConfigurationError
        A recorder is not available, a path fails the checks of
        :func:`~vjm_ros.logs.storage.check_log_path`, or a file cannot be opened.
    """
    recorders: list = []
    try:
        for _, opener in recorder_openers(model, settings, scene_text, **options):
            recorders.append(opener())
    except ConfigurationError:
        for rec in recorders:
            rec.close()
        raise
    return recorders
