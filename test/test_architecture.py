"""The package's layering holds (docs/design.md section 7), checked by import-linter.

The contracts live in ``setup.cfg`` (``[importlinter]``): each module imports only from the
layers below it, and only ``vjm_ros.ros`` imports rclpy (the physics, scenes, simulator and logs
run without ROS). import-linter builds the import graph from the source itself, so a new import
that crosses a layer fails here with the chain of imports that does it.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_import_contracts_are_kept():
    out = subprocess.run(
        [str(Path(sys.executable).with_name("lint-imports")), "setup.cfg", "--no-cache"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,  # a hang guard: the check takes ~1 s
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout
