"""``ipr --version``: the version, exit 0, and a warning when another distribution provides ``ipr``."""

from __future__ import annotations

import subprocess
import sys
from importlib import metadata

import pytest

import ipr
from ipr.cli import main


def test_version_prints_the_version_and_exits_0():
    completed = subprocess.run(
        [sys.executable, "-m", "ipr", "--version"], capture_output=True, text=True
    )
    assert completed.returncode == 0
    assert completed.stdout.startswith(f"ipr {ipr.__version__} (distribution ipr-shapes)")


@pytest.mark.parametrize(
    "providers, warned",
    [(["ipr-shapes"], False), (["ipr_shapes", "ipr"], True), ([], False)],
)
def test_version_warns_when_another_distribution_provides_ipr(
    providers: list[str], warned: bool, monkeypatch, capsys
):
    monkeypatch.setattr(metadata, "packages_distributions", lambda: {"ipr": providers})
    monkeypatch.setattr(metadata, "version", lambda name: "3.13.0")
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    captured = capsys.readouterr()
    assert captured.out.startswith(f"ipr {ipr.__version__}")
    assert ("ipr 3.13.0 is also installed" in captured.err) is warned
    assert ("ipr-shapes" in captured.err or "ipr_shapes" in captured.err) is warned  # the fix
