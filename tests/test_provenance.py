"""What a result records about how it was made (``provenance``, ``config.toml``), and the run's
progress as its observer hears it (``ipr_shapes.progress``) and as the command shows it."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import ipr_shapes
from ipr_shapes import cli, pipeline
from ipr_shapes import result as result_module
from ipr_shapes.config import Config, config_digest, read_config
from ipr_shapes.errors import IprError
from ipr_shapes.pipeline import infer, run_pipeline
from ipr_shapes.progress import ProgressEvent
from ipr_shapes.result import load_result
from ipr_shapes.scene import frames_digest, load_scene


def test_a_result_records_what_produced_it(scene_dir: Path, tmp_path: Path):
    config_file = tmp_path / "run.toml"
    config_file.write_text("[inference.likelihood]\nalpha_per_m = 8.0\n")
    out = infer(
        scene_dir,
        tmp_path / "result",
        method="collision-checker",
        seed=3,
        time_budget_s=60.0,
        config=read_config(config_file),
    )
    provenance = load_result(out, load_meshes=False).extra["provenance"]
    assert provenance["ipr_version"] == ipr_shapes.__version__
    assert provenance["distribution"] == "ipr-shapes"
    assert provenance["method"] == "collision-checker" and provenance["seed"] == 3
    assert provenance["budget"] == {"time_budget_s": 60.0, "samples": None, "workers": None}
    assert provenance["scene"] == str(scene_dir.resolve())
    assert provenance["frames"] == [0, 1]
    assert provenance["frames_digest"] == frames_digest(load_scene(scene_dir).frames)
    assert set(provenance["software"]) == {"python", "numpy", "mujoco"}
    assert provenance["created_utc"].endswith("+00:00")
    # The whole configuration is beside it, and is the one its digest names.
    assert provenance["config_file"] == "config.toml"
    written = read_config(out / "config.toml")
    assert written.inference.likelihood.alpha_per_m == 8.0
    assert config_digest(written) == provenance["config_digest"]
    assert provenance["config_digest"] != config_digest(Config())


def test_nothing_is_half_written_when_a_run_or_its_writing_fails(
    scene_dir: Path, tmp_path: Path, monkeypatch
):
    with pytest.raises(IprError, match="time-budget"):
        infer(scene_dir, tmp_path / "result", method="collision-checker", time_budget_s=-1.0)

    def broken(occupancy):
        raise OSError("disk full")

    monkeypatch.setattr(result_module, "_occupancy_arrays", broken)
    with pytest.raises(OSError, match="disk full"):
        infer(scene_dir, tmp_path / "result", method="collision-checker")
    assert [p.name for p in tmp_path.iterdir()] == ["scene"]  # no result, no staging folder


def test_the_observer_hears_every_stage_in_order(scene_dir: Path):
    events: list[ProgressEvent] = []
    scene = load_scene(scene_dir)
    run_pipeline(scene, method="ipr+action+uniform", samples=2, workers=1, progress=events.append)
    stages = [e.stage for e in events if e.stage != "compiling"]
    order = ["perception", "free_space", "fusion", "hypotheses", "sampling", "carving"]
    assert [s for s in order if s in stages] == sorted(set(stages), key=order.index)
    assert stages == sorted(stages, key=order.index)  # each stage's events together, in order
    # Perception advances frame by frame: segmentation, then each frame's free space.
    perception = [(e.done, e.total) for e in events if e.stage == "perception"]
    assert perception == [(0, 2), (1, 2), (2, 2)]
    free_space = [(e.done, e.total) for e in events if e.stage == "free_space"]
    assert free_space == [(0, 2), (1, 2), (2, 2)]
    hypotheses = [e for e in events if e.stage == "hypotheses"]
    assert hypotheses[0].done == 0 and hypotheses[-1].done == hypotheses[-1].total >= 1
    sampling = [e for e in events if e.stage == "sampling"]
    assert [e.done for e in sampling] == [0, 1, 2] and {e.total for e in sampling} == {2}
    assert all(e.seconds_left is None for e in sampling)  # a fixed count, no deadline


@pytest.mark.slow
def test_sampling_reports_the_time_left_under_a_budget(scene_dir: Path):
    events: list[ProgressEvent] = []
    run_pipeline(load_scene(scene_dir), time_budget_s=6.0, workers=1, progress=events.append)
    sampling = [e for e in events if e.stage == "sampling"]
    assert sampling and sampling[0].total is None
    lefts = [e.seconds_left for e in sampling]
    assert all(0.0 <= left <= 6.0 for left in lefts) and lefts == sorted(lefts, reverse=True)


def test_the_command_shows_no_progress_when_stderr_is_not_a_terminal(
    scene_dir: Path, tmp_path: Path
):
    completed = subprocess.run(
        [
            sys.executable,
            "-m",
            "ipr_shapes",
            "segment",
            str(scene_dir),
            "-o",
            str(tmp_path / "seg"),
        ],
        capture_output=True,
        text=True,
    )
    assert completed.returncode == 0 and completed.stderr == ""


def test_on_a_terminal_the_command_announces_compiling_and_draws_the_stages(
    scene_dir: Path, tmp_path: Path, monkeypatch
):
    from rich.console import Console

    screen = io.StringIO()
    make_progress = cli._progress
    terminal = Console(file=screen, force_terminal=True, width=120)
    monkeypatch.setattr(cli, "_progress", lambda: make_progress(terminal))
    monkeypatch.setattr(pipeline, "kernel_cache_cold", lambda: True)
    out = tmp_path / "result"
    assert cli.main(["infer", str(scene_dir), "-o", str(out), "--method", "collision-checker"]) == 0
    shown = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen.getvalue())  # no terminal codes
    assert shown.count(cli.COMPILING_NOTICE) == 1
    for label in ("perception (frames)", "hypotheses (objects)", "carving"):
        assert label in shown


def test_the_kernel_cache_is_cold_until_a_perception_finishes(tmp_path: Path, monkeypatch):
    marker = tmp_path / "cache" / "ipr-kernels-x.compiled"
    marker.parent.mkdir()
    monkeypatch.setattr(pipeline, "_kernel_cache_marker", lambda: marker)
    assert pipeline.kernel_cache_cold()
    pipeline.mark_kernel_cache_warm()
    assert marker.is_file() and not pipeline.kernel_cache_cold()
    monkeypatch.setattr(pipeline, "_kernel_cache_marker", lambda: None)  # cache unknown
    assert not pipeline.kernel_cache_cold()
    pipeline.mark_kernel_cache_warm()


def test_the_kernel_cache_marker_lies_in_numbas_cache_folder():
    marker = pipeline._kernel_cache_marker()
    assert marker is not None and marker.name.startswith("ipr-kernels-")
    assert marker.parent.is_dir() and any(marker.parent.glob("*.nbi"))


def test_the_result_lists_provenance_beside_the_contract_keys(scene_dir: Path, tmp_path: Path):
    out = infer(scene_dir, tmp_path / "r", method="collision-checker")
    document = json.loads((out / "result.json").read_text())
    assert {"format", "method", "world_from_camera", "objects", "timing_s"} <= set(document)
    assert "provenance" in document and (out / "config.toml").is_file()
    assert (out / "occupancy.npz").is_file()
