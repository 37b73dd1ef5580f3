"""Benchmark suites: every suite is offered by ``ipr-shapes suite``, and the real suites list the
shared data's scenes in place (skipped when the data is absent)."""

from __future__ import annotations

import pytest

from ipr_shapes.cli import build_parser
from ipr_shapes.data import bins_real_dir
from ipr_shapes.errors import IprError
from ipr_shapes.suites import REAL, SUITES, suite_scenes


def test_ipr_suite_offers_every_suite() -> None:
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command")
    name = next(a for a in commands.choices["suite"]._actions if a.dest == "name")
    assert list(name.choices) == [*SUITES, "all"]
    assert set(REAL) == {"ycbv-real", "bins-real"}


def test_unknown_suite_is_refused() -> None:
    with pytest.raises(IprError, match="choose one of .*bins-real"):
        suite_scenes("bins-fake")


def test_bins_real_suite_reads_the_shared_scenes_in_place() -> None:
    root = bins_real_dir()
    if root is None:
        pytest.skip("bins_real data (../shared/data/bins_real or $IPR_DATA) is absent")
    scenes = suite_scenes("bins-real")
    assert len(scenes) >= 15
    assert scenes == sorted(scenes) and all(scene.parent == root for scene in scenes)
    assert all((scene / "mask_visib").is_dir() for scene in scenes)
    assert "models" not in {scene.name for scene in scenes}
