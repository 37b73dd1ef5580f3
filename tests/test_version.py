"""``ipr-shapes --version``: the version and the distribution's name, exit 0."""

from __future__ import annotations

import subprocess
import sys

import ipr_shapes


def test_version_prints_the_version_and_exits_0():
    completed = subprocess.run(
        [sys.executable, "-m", "ipr_shapes", "--version"], capture_output=True, text=True
    )
    assert completed.returncode == 0
    assert completed.stdout.startswith(
        f"ipr-shapes {ipr_shapes.__version__} (distribution ipr-shapes)"
    )
