"""One thread per process for fair timing, and the study's progress line with its work estimate."""

from __future__ import annotations

import ctypes
import math
import os
import shutil
import sys
import time
from pathlib import Path

from vjm_ros.studies.bench.grid import (
    RowConfig,
)


def limit_threads() -> dict:
    """Keep BLAS and OpenMP on one thread, also when numpy is already loaded.

    Sets ``OMP_NUM_THREADS`` and friends for anything started later, and calls the loaded
    OpenBLAS's ``set_num_threads(1)``.

    Returns
    -------
    dict
        What was done (for the report).
    """
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
        os.environ[var] = "1"
    info = {"env": "OMP/OPENBLAS/MKL_NUM_THREADS=1", "blas": "not found"}
    try:
        with open("/proc/self/maps", encoding="utf-8") as fh:
            libs = sorted({ln.split()[-1] for ln in fh if "openblas" in ln.lower() and "/" in ln})
    except OSError:
        libs = []
    done = []
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for sym in ("openblas_set_num_threads", "scipy_openblas_set_num_threads64_",
                    "openblas_set_num_threads64_", "scipy_openblas_set_num_threads"):
            fn = getattr(lib, sym, None)
            if fn is not None:
                fn(ctypes.c_int(1))
                done.append(f"{Path(path).name}:{sym}(1)")
                break
    if done:
        info["blas"] = ", ".join(done)
    return info


# ---------------------------------------------------------------------------------------- progress
class BenchProgress:
    """A progress bar on stderr: redrawn in place on a terminal, a line per ~10 % otherwise.

    Parameters
    ----------
    total : float
        Total estimated work (arbitrary units).
    enabled : bool
    """

    def __init__(self, total: float, enabled: bool = True):
        self.total = max(total, 1e-9)
        self.stream = sys.stderr
        self.enabled = enabled
        self.done = 0.0
        self.start = time.perf_counter()
        self.last_draw = 0.0
        self.last_line_frac = -1.0
        self.tty = self.stream.isatty()

    def advance(self, work: float, label: str = "") -> None:
        """Count ``work`` as done and redraw."""
        self.done += work
        self.draw(label)

    def draw(self, label: str = "") -> None:
        """Redraw the bar with the current label."""
        if not self.enabled:
            return
        now = time.perf_counter()
        frac = min(self.done / self.total, 1.0)
        elapsed = now - self.start
        eta = elapsed * (1 - frac) / frac if frac > 0.01 else float("nan")
        eta_s = f"{eta / 60:4.1f} min" if math.isfinite(eta) else "   ?"
        width = 28
        filled = int(frac * width)
        bar = "#" * filled + "-" * (width - filled)
        text = f"[{bar}] {100 * frac:5.1f}%  {elapsed / 60:4.1f} min, eta {eta_s}  {label}"
        if self.tty:
            if now - self.last_draw < 0.1 and frac < 1.0:
                return
            self.last_draw = now
            cols = shutil.get_terminal_size((120, 20)).columns
            self.stream.write("\r" + text[: cols - 1].ljust(cols - 1))
        else:
            if frac - self.last_line_frac < 0.1 and frac < 1.0:
                return
            self.last_line_frac = frac
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _work(cfg: RowConfig, horizon: float) -> float:
    """Rough cost of one run, in model evaluations (for the progress estimate)."""
    if cfg.engine == "mujoco":
        return 0.02 * horizon * cfg.rate * cfg.substeps
    if cfg.adaptive:
        per_s = {"radau": 20000.0, "bdf": 8000.0, "lsoda": 6000.0}.get(cfg.integrator, 4000.0)
        return per_s * horizon
    stages = {"rk4": 4.0, "implicit_euler": 1.4}.get(cfg.integrator, 1.0)
    return stages * horizon * cfg.rate * cfg.substeps
