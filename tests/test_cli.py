"""The ``ipr`` command end to end: synth -> check -> ground-truth -> eval, help, and bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ipr_shapes.cli import EXIT_INPUT_ERROR, main


def _small_scene(tmp_path: Path, kind: str, seed: int, arrangement: str = "table") -> Path:
    """A generated 320x240 scene under ``tmp_path/scenes`` (what the end-to-end tests run on)."""
    from ipr_shapes.synth import SynthConfig, generate_scene

    return generate_scene(
        tmp_path / "scenes",
        kind=kind,
        seed=seed,
        arrangement=arrangement,
        config=SynthConfig(width=320, height=240),
    )


def test_help_lists_every_command():
    completed = subprocess.run(
        [sys.executable, "-m", "ipr_shapes", "--help"], capture_output=True, text=True
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


@pytest.mark.slow  # an end-to-end run of several seconds
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
        [sys.executable, "-m", "ipr_shapes", "check", str(tmp_path / "scene")],
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


@pytest.mark.slow
def test_segment_writes_labels_facets_and_overlays(tmp_path: Path, capsys):
    from PIL import Image

    scene = _small_scene(tmp_path, "dynamic", 5)
    out = tmp_path / "seg"
    assert main(["segment", str(scene), "-o", str(out)]) == 0
    summary = json.loads((out / "segmentation.json").read_text())
    frames = len(summary["frames"])
    assert frames >= 2
    ids_per_frame = []
    for index in range(frames):
        with Image.open(out / "labels" / f"{index:06d}.png") as picture:
            assert picture.mode == "P"  # ids as pixel values, colours in a viewer (label_png)
            labels = np.asarray(picture)
        facets = np.asarray(Image.open(out / "facets" / f"{index:06d}.png"))
        assert labels.shape == (240, 320) and facets.shape == labels.shape
        assert Image.open(out / "overlay" / f"{index:06d}.png").size == (320, 240)
        ids = set(np.unique(labels)) - {0}
        assert ids == {obj["id"] for obj in summary["frames"][index]["objects"]}
        assert (facets[labels == 0] == 0).all()  # facets only on objects
        ids_per_frame.append(ids)
    assert len(ids_per_frame[0]) >= 3
    assert set(summary["object_ids"]) == set().union(*ids_per_frame)
    # Refuses to overwrite, and leaves nothing half-written.
    assert main(["segment", str(scene), "-o", str(out)]) == EXIT_INPUT_ERROR
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scenes", "seg"]


@pytest.mark.slow
def test_infer_collision_checker_end_to_end(tmp_path: Path, capsys):
    from ipr_shapes.result import load_result

    scene = _small_scene(tmp_path, "static", 2)
    out = tmp_path / "result"
    assert (
        main(["infer", str(scene), "-o", str(out), "--method", "collision-checker", "--seed", "1"])
        == 0
    )
    result = load_result(out)
    assert result.method == "collision-checker" and len(result.objects) >= 2
    for obj in result.objects:
        assert abs(sum(h.probability for h in obj.hypotheses) - 1.0) < 1e-6
        assert obj.load_mesh().is_watertight
    assert set(result.timing_s) >= {"segmentation", "hypotheses", "inference", "carving", "total"}
    # The written shapes are carved by the space frame 0 saw empty: no longer convex.
    summary = result.extra["objects_summary"]
    assert any(entry["carved"] for entry in summary)
    for obj, entry in zip(result.objects, summary, strict=True):
        mesh = obj.load_mesh()
        if entry["carved"]:
            assert mesh.volume < entry["best_volume_m3"]
    metrics_file = tmp_path / "metrics.json"
    assert main(["eval", str(scene), str(out), "--json", str(metrics_file)]) == 0
    metrics = json.loads(metrics_file.read_text())
    # A real but imperfect reconstruction: well above nothing, below the ground truth.
    assert 0.2 < metrics["scene_space"]["iou"] < 0.99
    # Same seed, same answer.
    again = tmp_path / "again"
    again_args = ["infer", str(scene), "-o", str(again), "--seed", "1"]
    assert main([*again_args, "--method", "collision-checker"]) == 0
    first = [o.load_mesh().volume for o in result.objects]
    second = [o.load_mesh().volume for o in load_result(again).objects]
    assert np.allclose(first, second)
    # Without carving the convex hypotheses are written as inferred.
    convex = tmp_path / "convex"
    assert main([*again_args[:3], str(convex), "--seed", "1", "--no-carving", "--method",
                 "collision-checker"]) == 0  # fmt: skip
    uncarved = load_result(convex)
    assert not any(entry["carved"] for entry in uncarved.extra["objects_summary"])
    volumes = [o.load_mesh().volume for o in uncarved.objects]
    assert np.allclose(volumes, [e["best_volume_m3"] for e in summary], rtol=1e-4)
    assert all(v >= c - 1e-12 for v, c in zip(volumes, first, strict=True))
    assert sum(volumes) > sum(first)


def test_infer_rejects_bad_budget_and_existing_output(scene_dir: Path, tmp_path: Path, capsys):
    assert (
        main(["infer", str(scene_dir), "-o", str(tmp_path / "r"), "--time-budget", "-1"])
        == EXIT_INPUT_ERROR
    )
    assert "time-budget" in capsys.readouterr().err
    (tmp_path / "exists").mkdir()
    assert main(["infer", str(scene_dir), "-o", str(tmp_path / "exists")]) == EXIT_INPUT_ERROR
    assert "already exists" in capsys.readouterr().err


def test_segment_and_infer_on_an_empty_table_give_empty_results(tmp_path: Path):
    from ipr_shapes.camera import look_at
    from ipr_shapes.result import load_result
    from ipr_shapes.scene import Frame, write_scene

    K = np.array([[150.0, 0, 79.5], [0, 150.0, 59.5], [0, 0, 1]])
    world_from_camera = look_at(np.array([0.0, -0.45, 0.45]), np.zeros(3))
    u, v = np.meshgrid(np.arange(160), np.arange(120))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((120, 160))], -1)
    rays_world = rays @ world_from_camera[:3, :3].T
    depth = (-world_from_camera[2, 3] / rays_world[..., 2]).astype(np.float32)
    rgb = np.full((120, 160, 3), 120, np.uint8)
    scene = write_scene(tmp_path / "empty", [Frame(0, rgb, depth, K, world_from_camera)])
    assert main(["segment", str(scene), "-o", str(tmp_path / "seg")]) == 0
    summary = json.loads((tmp_path / "seg" / "segmentation.json").read_text())
    assert summary["object_ids"] == [] and summary["frames"][0]["planes"][0]["kind"] == "support"
    assert main(["infer", str(scene), "-o", str(tmp_path / "result")]) == 0
    assert load_result(tmp_path / "result").objects == ()


def test_segment_without_support_plane_fails_clearly(tmp_path: Path):
    from ipr_shapes.scene import Frame, write_scene

    from .conftest import make_frames

    frame = make_frames(1)[0]
    noise = np.random.default_rng(0).uniform(0.4, 1.5, frame.depth_m.shape).astype(np.float32)
    scene = write_scene(
        tmp_path / "noise", [Frame(0, frame.rgb, noise, frame.K, frame.world_from_camera)]
    )
    completed = subprocess.run(
        [sys.executable, "-m", "ipr_shapes", "segment", str(scene), "-o", str(tmp_path / "out")],
        capture_output=True,
        text=True,
    )
    assert completed.returncode == EXIT_INPUT_ERROR
    assert (
        "frame 0: no support plane found" in completed.stderr
        and "Traceback" not in completed.stderr
    )
    assert not (tmp_path / "out").exists()


def test_synth_rejects_zero_width(tmp_path: Path, capsys):
    assert (
        main(["synth", str(tmp_path / "s"), "--kind", "static", "--width", "0"]) == EXIT_INPUT_ERROR
    )
    assert "width" in capsys.readouterr().err
    assert not (tmp_path / "s").exists() or not any((tmp_path / "s").iterdir())


def test_ground_truth_of_a_scene_without_ground_truth_fails_clearly(
    scene_dir: Path, tmp_path, capsys
):
    assert main(["ground-truth", str(scene_dir), "-o", str(tmp_path / "gt")]) == EXIT_INPUT_ERROR
    assert "has no ground truth" in capsys.readouterr().err
    assert not (tmp_path / "gt").exists()


@pytest.mark.slow
def test_infer_default_method_writes_the_full_result_and_is_reproducible(tmp_path: Path, capsys):
    from PIL import Image

    from ipr_shapes.inference import InferenceConfig
    from ipr_shapes.result import load_result

    scene = _small_scene(tmp_path, "dynamic", 4)
    runs = []
    for workers in ("1", "2"):
        out = tmp_path / f"result-{workers}"
        args = ["infer", str(scene), "-o", str(out), "--samples", "3", "--workers", workers]
        assert main(args) == 0
        assert "3 samples" in capsys.readouterr().out
        result = load_result(out)
        assert result.method == "ipr+action+uniform" and len(result.objects) >= 2
        details = result.extra["inference"]
        assert details["samples"] == 3 and details["fallback"] is None
        assert details["pushes_replayed"] >= 1 and details["frames_compared"] >= 2
        # By default one friction, the physics' (the search is opt-in), with posterior 1.
        assert details["frictions"] == [InferenceConfig().physics.friction]
        assert sum(details["friction_posterior"]) == pytest.approx(1.0)
        assert len(details["friction_posterior"]) == len(details["frictions"])
        assert set(result.timing_s) >= {
            "segmentation",
            "fusion",
            "hypotheses",
            "inference",
            "carving",
        }
        # Each object the pushes moved is fused with the later frames that saw it.
        assert set(details["fused_views"]) <= {str(obj.id) for obj in result.objects}
        assert all(set(frames) <= {1, 2, 3} for frames in details["fused_views"].values())
        for obj in result.objects:
            assert abs(sum(h.probability for h in obj.hypotheses) - 1.0) < 1e-6
            assert obj.load_mesh().is_watertight
        with Image.open(out / "completion.png") as picture:
            assert picture.size == (640, 240)  # the input beside the completed objects
        assert (out / "report.html").is_file() and (out / "labels" / "000000.png").is_file()
        runs.append([o.load_mesh().volume for o in result.objects])
    assert np.allclose(runs[0], runs[1])  # same seed and samples, any number of workers


@pytest.mark.slow  # an end-to-end run of several seconds
def test_infer_with_the_friction_searched_reports_its_posterior(tmp_path: Path, capsys):
    from ipr_shapes.result import load_result

    scene = _small_scene(tmp_path, "dynamic", 4)
    config = tmp_path / "friction.toml"
    config.write_text("[inference]\nfrictions = [0.25, 0.5, 1.0]\n")
    out = tmp_path / "result"
    args = ["infer", str(scene), "-o", str(out), "--samples", "2", "--config", str(config)]
    assert main(args) == 0
    details = load_result(out).extra["inference"]
    assert details["frictions"] == [0.25, 0.5, 1.0]
    assert len(details["friction_posterior"]) == 3
    assert sum(details["friction_posterior"]) == pytest.approx(1.0)
    assert "frictions = [" in (out / "config.toml").read_text()


@pytest.mark.slow  # an end-to-end run of several seconds
def test_infer_with_a_budget_too_small_for_one_sample_falls_back_and_says_so(
    tmp_path: Path, capsys
):
    from ipr_shapes.result import load_result
    from ipr_shapes.synth import SynthConfig, generate_scene

    scene = generate_scene(
        tmp_path / "scenes", kind="static", seed=5, config=SynthConfig(width=320, height=240)
    )
    out = tmp_path / "result"
    assert main(["infer", str(scene), "-o", str(out), "--time-budget", "0.05"]) == 0
    assert "Collision Checker" in capsys.readouterr().out
    assert load_result(out).extra["inference"]["fallback"]
    assert load_result(out).extra["inference"]["friction_posterior"] is None


def test_infer_rejects_bad_worker_and_sample_counts(scene_dir: Path, tmp_path: Path, capsys):
    for flag in ("--workers", "--samples"):
        with pytest.raises(SystemExit) as exit_info:
            main(["infer", str(scene_dir), "-o", str(tmp_path / "r"), flag, "0"])
        assert exit_info.value.code == 2
        assert "at least 1" in capsys.readouterr().err


def _listing(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("command", ["infer", "segment", "ground-truth"])
def test_no_output_may_replace_the_input_scene(command: str, scene_dir: Path, capsys):
    """The output folder is replaced whole when it is written: the scene itself, a folder
    inside it and a folder holding it are all refused before any work, with --overwrite too."""
    before = _listing(scene_dir.parent)
    for out in (scene_dir, scene_dir / "result", scene_dir.parent):
        code = main([command, str(scene_dir), "-o", str(out), "--overwrite"])
        assert code == EXIT_INPUT_ERROR, out
        error = capsys.readouterr().err
        assert "would replace the input" in error and len(error.strip().splitlines()) == 1
    assert _listing(scene_dir.parent) == before


def test_an_output_path_through_a_file_is_refused_before_the_run(scene_dir: Path, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["segment", str(scene_dir), "-o", str(blocker)]) == EXIT_INPUT_ERROR
    assert main(["segment", str(scene_dir), "-o", str(blocker / "out")]) == EXIT_INPUT_ERROR
    assert blocker.read_text() == "x"


@pytest.mark.parametrize("command", ["segment", "infer", "check", "batch"])
def test_up_option_is_documented(command: str, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--up X Y Z" in text and "up direction in camera coordinates" in text


@pytest.mark.slow  # several seconds: keeps `make test` under 3 minutes on 2 cores
def test_gravity_that_cannot_be_determined_is_said_clearly(tmp_path: Path):
    """No camera pose and no plane in frame 0: one line naming the frame and both fixes, a
    non-zero exit and no output."""
    from ipr_shapes.scene import Frame, write_scene

    from .conftest import make_frames

    frame = make_frames(1)[0]
    noise = np.random.default_rng(0).uniform(0.4, 1.5, frame.depth_m.shape).astype(np.float32)
    scene = write_scene(
        tmp_path / "noise",
        [Frame(0, frame.rgb, noise, frame.K, frame.world_from_camera)],
        write_poses=False,
    )
    for command in (["segment", str(scene), "-o", str(tmp_path / "out")], ["check", str(scene)]):
        completed = subprocess.run(
            [sys.executable, "-m", "ipr_shapes", *command], capture_output=True, text=True
        )
        assert completed.returncode == EXIT_INPUT_ERROR
        error = completed.stderr
        assert "frame 0: cannot determine gravity" in error and "Traceback" not in error
        assert "cam_R_w2c" in error and "--up X Y Z" in error
        assert len(error.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_segment_and_check_take_the_up_direction(tmp_path: Path, capsys):
    from ipr_shapes.scene import load_scene, write_scene

    from .conftest import make_frames

    frames = make_frames(1)
    scene = write_scene(tmp_path / "s", frames, write_poses=False)
    up = frames[0].world_from_camera[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    given = [f"{value:.3f}" for value in up]
    assert main(["check", str(scene), "--up", *given]) == 0
    assert "world frame from support_plane" in capsys.readouterr().out
    assert main(["segment", str(scene), "-o", str(tmp_path / "seg"), "--up", *given]) == 0
    summary = json.loads((tmp_path / "seg" / "segmentation.json").read_text())
    assert summary["frames"][0]["planes"][0]["kind"] == "support"
    assert np.allclose(load_scene(scene, up_camera=up).frames[0].world_from_camera[2, :3] @ up, 1)
    # A wrong up: refused before any output, for every command that loads the scene.
    down = [f"{-value:.3f}" for value in up]
    for command in (
        ["check", str(scene)],
        ["segment", str(scene), "-o", str(tmp_path / "seg2")],
        ["infer", str(scene), "-o", str(tmp_path / "result")],
    ):
        assert main([*command, "--up", *down]) == EXIT_INPUT_ERROR
        assert "camera is below the support" in capsys.readouterr().err
    assert not (tmp_path / "seg2").exists() and not (tmp_path / "result").exists()


def test_up_is_refused_for_a_scene_with_camera_poses(scene_dir: Path, tmp_path: Path, capsys):
    command = ["infer", str(scene_dir), "-o", str(tmp_path / "r"), "--up", "0", "0", "1"]
    assert main(command) == EXIT_INPUT_ERROR
    assert "camera poses, which fix gravity" in capsys.readouterr().err


@pytest.mark.slow
def test_collision_checker_with_views_fuses_the_later_frames_without_physics(
    tmp_path: Path, capsys
) -> None:
    from ipr_shapes.result import load_result

    scene = _small_scene(tmp_path, "dynamic", 4)
    volumes = {}
    for method in ("collision-checker", "collision-checker+views"):
        out = tmp_path / method
        assert main(["infer", str(scene), "-o", str(out), "--method", method]) == 0
        result = load_result(out)
        assert result.method == method
        details = result.extra.get("inference", {})
        assert "samples" not in details  # no physics: nothing sampled
        if method == "collision-checker":
            assert "fusion" not in result.timing_s and not details.get("fused_views")
        else:
            # The pushes moved objects: the later frames that saw them are fused into frame 0.
            assert "fusion" in result.timing_s and details["fused_views"]
        volumes[method] = sorted(o.load_mesh().volume for o in result.objects)
    # The views carve and bound the hidden parts: the shapes are not those of frame 0 alone.
    assert volumes["collision-checker"] != volumes["collision-checker+views"]
