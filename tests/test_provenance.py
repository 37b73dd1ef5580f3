"""What a result records about how it was made (``provenance``, ``config.toml``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import ipr
from ipr import result as result_module
from ipr.config import Config, config_digest, read_config
from ipr.errors import IprError
from ipr.pipeline import infer
from ipr.result import load_result


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
    assert provenance["ipr_version"] == ipr.__version__
    assert provenance["distribution"] == "ipr-shapes"
    assert provenance["method"] == "collision-checker" and provenance["seed"] == 3
    assert provenance["budget"] == {"time_budget_s": 60.0, "samples": None, "workers": None}
    assert provenance["scene"] == str(scene_dir.resolve())
    assert provenance["frames"] == [0, 1]
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


def test_the_result_lists_provenance_beside_the_contract_keys(scene_dir: Path, tmp_path: Path):
    out = infer(scene_dir, tmp_path / "r", method="collision-checker")
    document = json.loads((out / "result.json").read_text())
    assert {"format", "method", "world_from_camera", "objects", "timing_s"} <= set(document)
    assert "provenance" in document and (out / "config.toml").is_file()
    assert (out / "occupancy.npz").is_file()
