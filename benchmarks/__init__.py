"""Developer measurements of vjm_ros: run from a checkout, never installed.

Each module is a program, ``python -m benchmarks.NAME`` from the repository root (``README.md``
here lists them, with what each measures). They import the installed ``vjm_ros`` and may import
rclpy themselves: the package's layering (``setup.cfg``) binds ``vjm_ros`` only.
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository root: the working directory of the benchmark processes they start themselves
(``python -m benchmarks.NAME`` finds the ``benchmarks`` package there)."""
