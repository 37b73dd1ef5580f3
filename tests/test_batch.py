"""``ipr batch``: many scenes, one result each, resumable, failures reported, scores."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ipr.batch import find_scenes
from ipr.cli import EXIT_INPUT_ERROR, main
from ipr.errors import IprError


def test_scenes_are_found_in_folders_of_scenes_and_globs(scene_dir: Path, tmp_path: Path):
    assert find_scenes([scene_dir]) == [scene_dir]
    assert find_scenes([scene_dir.parent]) == [scene_dir]
    assert find_scenes([str(scene_dir.parent / "sc*")]) == [scene_dir]
    assert find_scenes([scene_dir, scene_dir.parent]) == [scene_dir]  # each once
    with pytest.raises(IprError, match="no scene folder"):
        find_scenes([tmp_path / "nothing-here"])
    twin = tmp_path / "elsewhere" / scene_dir.name
    twin.mkdir(parents=True)
    (twin / "scene_camera.json").write_text("{}")
    with pytest.raises(IprError, match="same folder name"):
        find_scenes([scene_dir, twin])


def test_a_batch_output_inside_a_scene_is_refused(scene_dir: Path, capsys):
    before = sorted(p.name for p in scene_dir.iterdir())
    assert main(["batch", str(scene_dir), "-o", str(scene_dir / "out")]) == EXIT_INPUT_ERROR
    assert "would replace the input" in capsys.readouterr().err
    assert sorted(p.name for p in scene_dir.iterdir()) == before


@pytest.mark.slow
@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_batch_runs_scores_resumes_and_reports_failures(tmp_path: Path, jobs: str, capsys):
    scenes = tmp_path / "scenes"
    synth = ["synth", str(scenes), "--kind", "static", "--seed", "5", "--count", "2"]
    assert main([*synth, "--width", "320", "--height", "240"]) == 0
    broken = scenes / "static_broken"
    broken.mkdir()
    (broken / "scene_camera.json").write_text("{not json")
    out = tmp_path / "out"
    run = ["batch", str(scenes), "-o", str(out), "--method", "collision-checker", "--jobs", jobs]
    assert main(run) == 1  # one scene failed, the others ran
    summary = json.loads((out / "summary.json").read_text())
    status = {Path(o["scene"]).name: o for o in summary["outcomes"]}
    assert [status[f"static_00000{i}"]["status"] for i in (0, 1)] == ["done", "done"]
    for i in (0, 1):
        row = status[f"static_00000{i}"]
        assert row["objects"] >= 1 and 0.0 < row["object_iou"] <= 1.0
        assert (out / f"static_00000{i}" / "result.json").is_file()
    assert status["static_broken"]["status"] == "failed"
    assert "scene_camera.json" in status["static_broken"]["error"]
    assert not (out / "static_broken").exists()  # nothing half-written
    assert "static_broken" in (out / "summary.md").read_text()
    # Rerun: finished results are kept, not recomputed; the fixed scene now runs.
    broken.rename(tmp_path / "set-aside")
    stamp = (out / "static_000000" / "result.json").stat().st_mtime_ns
    assert main(run) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {o["status"] for o in summary["outcomes"]} == {"kept"}
    assert (out / "static_000000" / "result.json").stat().st_mtime_ns == stamp
    assert "0 run, 2 kept, 0 failed" in capsys.readouterr().out
