"""The whole chain on a real bin-picking scene (boxes in mm, 8-vertex models, no camera pose):
the oracle scores 1 with boxes of their true volume, ``ipr-shapes infer --method
collision-checker`` then ``ipr-shapes eval`` produce a scored result, and the bin's far wall is
found as a wall. Skipped without the data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ipr_shapes.cli import main
from ipr_shapes.data import bins_real_dir
from ipr_shapes.metrics import evaluate
from ipr_shapes.perception.config import PerceptionConfig, WallsConfig
from ipr_shapes.perception.segmentation import segment_frame
from ipr_shapes.scene import load_model, load_scene

SCENE = "bins_000"  # 14 annotated boxes, all visible: 8 soap bars and 6 toothpaste boxes


@pytest.fixture
def bins_scene() -> Path:
    root = bins_real_dir()
    if root is None or not (root / SCENE).is_dir():
        pytest.skip("bins_real data (../shared/data/bins_real or $IPR_DATA) is absent")
    return root / SCENE


def test_ground_truth_of_a_bin_scene_scores_one_with_true_box_volumes(
    bins_scene: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / "gt"
    assert main(["ground-truth", str(bins_scene), "-o", str(out)]) == 0
    evaluation = evaluate(bins_scene, out)
    assert evaluation.visibility_source == "scene_gt_info"
    assert evaluation.n_visible == evaluation.n_ground_truth == 14
    assert evaluation.scene_space.iou == evaluation.object_space.iou == 1.0
    models = bins_scene.parent / "models"
    for row in evaluation.ground_truth:  # mm models scaled to metres, voxelised whole
        volume = load_model(models, row.obj_id).volume
        assert row.voxels == pytest.approx(volume / 0.005**3, rel=0.1)


@pytest.mark.slow
def test_collision_checker_then_eval_on_a_bin_scene(
    bins_scene: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / "cc"
    command = ["infer", str(bins_scene), "-o", str(out), "--method", "collision-checker"]
    assert main([*command, "--seed", "1", "--workers", "1"]) == 0
    metrics = tmp_path / "metrics.json"
    assert main(["eval", str(bins_scene), str(out), "--json", str(metrics)]) == 0
    report = capsys.readouterr().out
    assert "visible objects 14/14" in report
    scored = json.loads(metrics.read_text())
    assert scored["method"] == "collision-checker" and scored["n_predicted"] >= 1
    for space in ("scene_space", "object_space"):
        assert 0.0 <= scored[space]["iou"] <= 1.0
    assert len(scored["ground_truth"]) == 14


def test_the_bins_far_wall_is_a_wall_though_its_foot_is_hidden_and_its_top_leaves_the_image(
    bins_scene: Path,
) -> None:
    # bins_000's camera looks down into the bin: the far wall fills the top of the image, its
    # foot hidden behind the boxes and its top edge mostly the image's border. It is a wall
    # only when both are read as what the camera could not see (not free space, not a top).
    frame = load_scene(bins_scene).frames[0]
    far_wall = np.zeros(frame.shape, dtype=bool)
    far_wall[:30] = frame.depth_m[:30] > 0

    def labelled(walls: WallsConfig) -> float:
        result = segment_frame(frame, config=PerceptionConfig(walls=walls))
        return float(np.mean(result.labels[far_wall] > 0))

    assert labelled(WallsConfig()) < 0.15
    assert labelled(WallsConfig(hidden_bottom=False)) > 0.5
    assert labelled(WallsConfig(frame_cut_tops=False)) > 0.5
