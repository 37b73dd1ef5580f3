"""The ``ipr`` command end to end: synth -> check -> ground-truth -> eval, help, and bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ipr.cli import EXIT_INPUT_ERROR, main


def test_help_lists_every_command():
    completed = subprocess.run(
        [sys.executable, "-m", "ipr", "--help"], capture_output=True, text=True
    )
    assert completed.returncode == 0
    for command in ("synth", "eval", "ground-truth", "check", "suite"):
        assert command in completed.stdout


@pytest.mark.parametrize("command", ["synth", "eval", "ground-truth", "check", "suite"])
def test_each_command_has_help(command: str, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: ipr" in capsys.readouterr().out


def test_synth_then_eval_scores_ground_truth_perfectly(tmp_path: Path, capsys):
    out = tmp_path / "scenes"
    assert (
        main(
            [
                "synth",
                str(out),
                "--kind",
                "dynamic",
                "--seed",
                "3",
                "--count",
                "1",
                "--width",
                "320",
                "--height",
                "240",
            ]
        )
        == 0
    )
    (scene,) = [Path(line) for line in capsys.readouterr().out.split()]
    assert scene.parent == out and (out / "models").is_dir() and (scene / "preview.png").is_file()
    assert main(["check", str(scene)]) == 0
    assert "valid scene" in capsys.readouterr().out
    result = tmp_path / "gt"
    assert main(["ground-truth", str(scene), "-o", str(result)]) == 0
    metrics_file = tmp_path / "metrics.json"
    assert main(["eval", str(scene), str(result), "--json", str(metrics_file)]) == 0
    table = capsys.readouterr().out
    assert "scene" in table.lower() and "object" in table.lower()
    metrics = json.loads(metrics_file.read_text())
    assert metrics["scene_space"]["iou"] >= 0.99
    assert metrics["object_space"]["iou"] >= 0.99


def test_bad_scene_gives_one_line_error_and_nonzero_exit(tmp_path: Path):
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "scene_camera.json").write_text("{not json")
    completed = subprocess.run(
        [sys.executable, "-m", "ipr", "check", str(tmp_path / "scene")],
        capture_output=True,
        text=True,
    )
    assert completed.returncode == EXIT_INPUT_ERROR
    assert "scene_camera.json" in completed.stderr and "not valid JSON" in completed.stderr
    assert "Traceback" not in completed.stderr


def test_eval_of_malformed_result_fails_clearly(scene_dir: Path, tmp_path: Path, capsys):
    result = tmp_path / "result"
    result.mkdir()
    (result / "result.json").write_text(json.dumps({"format": "something-else/2"}))
    assert main(["eval", str(scene_dir), str(result)]) == EXIT_INPUT_ERROR
    assert "result.json" in capsys.readouterr().err


def test_synth_rejects_bad_count(tmp_path: Path, capsys):
    assert main(["synth", str(tmp_path), "--kind", "static", "--count", "0"]) == EXIT_INPUT_ERROR
    assert "count" in capsys.readouterr().err


def test_eval_json_is_not_half_written_on_error(scene_dir: Path, tmp_path: Path):
    target = tmp_path / "metrics.json"
    assert main(["eval", str(scene_dir), str(tmp_path / "missing"), "--json", str(target)]) != 0
    assert not target.exists()
