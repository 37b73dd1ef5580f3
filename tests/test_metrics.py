"""Metrics: the oracle scores 1, known errors score their analytic or independently computed
value, matching is order-independent, unmatched and invisible objects follow the contract."""

import json
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ipr_shapes import voxels
from ipr_shapes.camera import invert_transform, look_at
from ipr_shapes.data import ycbv_real_dir
from ipr_shapes.ground_truth import write_ground_truth_result
from ipr_shapes.metrics import evaluate, format_table, scores
from ipr_shapes.rendering import render_depth_and_ids
from ipr_shapes.result import load_result, write_result
from ipr_shapes.scene import Frame, ObjectPose, load_ground_truth, load_model, write_scene

K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
WIDTH, HEIGHT = 320, 240
TARGET = np.array([0.05, 0.05, 0.05])  # centre of the grid-aligned box [0, 0.1]^3
EYE = np.array([0.05, -0.55, 0.75])
WORLD_FROM_CAMERA = look_at(EYE, TARGET)
VIEW = (TARGET - EYE) / np.linalg.norm(TARGET - EYE)


def _translation(offset) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, 3] = offset
    return transform


def _box(size: float, centre=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(size, size, size))
    box.apply_translation(centre)
    return box


def _box_scene(root: Path, boxes, *, visible_px=None, occluders=()) -> Path:
    """A one-frame BOP scene of cubes: ``boxes`` = [(obj_id, size_m, world centre)]. The
    observed depth is rendered from the cubes plus ``occluders`` (meshes in the world that are
    not ground truth) in front of a wall at 1.5 m."""
    models = root / "models"
    models.mkdir(parents=True, exist_ok=True)
    for obj_id, size, _ in boxes:
        _box(size * 1000.0).export(models / f"obj_{obj_id:06d}.ply")  # BOP models are in mm
    meshes = [_box(size, centre) for _, size, centre in boxes] + list(occluders)
    depth, index = render_depth_and_ids(
        meshes, [None] * len(meshes), K, WIDTH, HEIGHT, WORLD_FROM_CAMERA
    )
    depth[index < 0] = 1.5
    frame = Frame(0, np.zeros((HEIGHT, WIDTH, 3), np.uint8), depth, K, WORLD_FROM_CAMERA)
    camera_from_world = invert_transform(WORLD_FROM_CAMERA)
    poses = [
        ObjectPose(obj_id, camera_from_world @ _translation(centre)) for obj_id, _, centre in boxes
    ]
    info = None
    if visible_px is not None:
        info = {0: [{"px_count_visib": int(n)} for n in visible_px]}
    return write_scene(root / "scene", [frame], ground_truth={0: poses}, ground_truth_info=info)


def _result(path: Path, meshes, world_from_camera=WORLD_FROM_CAMERA) -> Path:
    return write_result(path, "test", {0: world_from_camera}, [(m, []) for m in meshes], {})


def _figures(s):
    return (s.iou, s.precision, s.recall, s.f1)


BOX_1 = (1, 0.1, (0.05, 0.05, 0.05))  # occupies [0, 0.1]^3: exactly 20^3 voxels
BOX_2 = (2, 0.1, (0.25, 0.05, 0.05))


# --------------------------------------------------------------------------------------------
# Synthetic scenes with analytic answers


def test_score_rules():
    assert _figures(scores(0, 0, 0)) == (1.0, 1.0, 1.0, 1.0)
    assert _figures(scores(0, 10, 0)) == (0.0, 0.0, 0.0, 0.0)
    assert _figures(scores(10, 0, 0)) == (0.0, 0.0, 0.0, 0.0)
    s = scores(10, 20, 5)
    assert _figures(s) == pytest.approx((5 / 25, 0.5, 0.25, 2 * 0.5 * 0.25 / 0.75))


def test_box_shifted_by_a_tenth_scores_nine_elevenths(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1])
    result = _result(tmp_path / "res", [_box(0.1, (0.06, 0.05, 0.05))])
    evaluation = evaluate(scene, result)
    for space in (evaluation.scene_space, evaluation.object_space):
        assert _figures(space) == pytest.approx((9 / 11, 0.9, 0.9, 0.9), abs=1e-12)
    assert evaluation.ground_truth[0].voxels == 8000
    assert evaluation.visibility_source == "rendered" and evaluation.n_visible == 1
    exact = evaluate(scene, _result(tmp_path / "exact", [_box(0.1, (0.05, 0.05, 0.05))]))
    assert _figures(exact.scene_space) == (1.0, 1.0, 1.0, 1.0)


def test_unmatched_ground_truth_scores_zero(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1, BOX_2])
    evaluation = evaluate(scene, _result(tmp_path / "res", [_box(0.1, BOX_2[2])]))
    rows = {row.obj_id: row for row in evaluation.ground_truth}
    assert rows[1].matched_id is None and _figures(rows[1].scores) == (0.0, 0.0, 0.0, 0.0)
    assert rows[2].matched_id == 0 and _figures(rows[2].scores) == (1.0, 1.0, 1.0, 1.0)
    assert _figures(evaluation.object_space) == pytest.approx((0.5, 0.5, 0.5, 0.5))
    assert _figures(evaluation.scene_space) == pytest.approx((0.5, 1.0, 0.5, 2 / 3))
    assert evaluation.n_matched == 1
    empty = evaluate(scene, _result(tmp_path / "empty", []))
    assert _figures(empty.scene_space) == _figures(empty.object_space) == (0.0, 0.0, 0.0, 0.0)


def test_prediction_overlapping_nothing_counts_in_scene_space_only(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1])
    result = _result(tmp_path / "res", [_box(0.1, (0.6, 0.6, 0.05)), _box(0.1, BOX_1[2])])
    evaluation = evaluate(scene, result)
    assert _figures(evaluation.scene_space) == pytest.approx((0.5, 0.5, 1.0, 2 / 3))
    assert _figures(evaluation.object_space) == (1.0, 1.0, 1.0, 1.0)
    stray, match = evaluation.predictions
    assert (stray.id, stray.matched_gt_index, stray.voxels) == (0, None, 8000)
    assert (match.id, match.matched_gt_index) == (1, 0)
    assert "unmatched predictions: ids [0]" in format_table(evaluation)


def test_objects_hidden_by_scene_gt_info_are_excluded(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1, BOX_2], visible_px=[5000, 99])
    evaluation = evaluate(scene, _result(tmp_path / "res", [_box(0.1, BOX_1[2])]))
    assert evaluation.visibility_source == "scene_gt_info"
    assert (evaluation.n_ground_truth, evaluation.n_visible) == (2, 1)
    assert _figures(evaluation.scene_space) == _figures(evaluation.object_space) == (1, 1, 1, 1)
    hidden = evaluation.ground_truth[1]
    assert not hidden.visible and hidden.scores is None and hidden.matched_id is None
    # Predicting the hidden object is a false positive in scene space.
    both = evaluate(scene, _result(tmp_path / "both", [_box(0.1, c) for c in (BOX_1[2], BOX_2[2])]))
    assert _figures(both.scene_space) == pytest.approx((0.5, 0.5, 1.0, 2 / 3))
    # A lower threshold makes it visible again.
    lenient = evaluate(scene, tmp_path / "both", min_visible_px=99)
    assert lenient.n_visible == 2 and _figures(lenient.scene_space) == (1, 1, 1, 1)


def test_rendered_visibility_excludes_occluded_objects(tmp_path):
    # Object 2 sits right behind object 1 on the viewing ray (front-most rule); object 3 is in
    # the open but an unmodelled plate hides it in the observed depth (depth rule).
    behind = tuple(TARGET + 0.12 * VIEW)
    aside = (0.3, 0.05, 0.05)
    towards_eye = (EYE - aside) / np.linalg.norm(EYE - aside)
    plate_centre = np.array(aside) + 0.3 * towards_eye
    plate = _box(0.08, plate_centre)
    boxes = [BOX_1, (2, 0.02, behind), (3, 0.04, aside)]
    scene = _box_scene(tmp_path, boxes, occluders=[plate])
    evaluation = evaluate(scene, _result(tmp_path / "res", [_box(0.1, BOX_1[2])]))
    assert evaluation.visibility_source == "rendered"
    assert [row.visible for row in evaluation.ground_truth] == [True, False, False]
    assert evaluation.ground_truth[0].visible_px > 1000
    assert _figures(evaluation.scene_space) == _figures(evaluation.object_space) == (1, 1, 1, 1)
    # Without the plate, object 3 is visible (and unpredicted).
    open_scene = _box_scene(tmp_path / "open", boxes)
    opened = evaluate(open_scene, tmp_path / "res")
    assert [row.visible for row in opened.ground_truth] == [True, False, True]
    assert opened.object_space.iou == pytest.approx(0.5)


def test_open_predicted_mesh_is_scored_as_its_convex_hull(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1])
    box = _box(0.1, BOX_1[2])
    x = box.vertices[box.faces][:, :, 0]
    walls = box.faces[np.all(np.isclose(x, 0.0), axis=1) | np.all(np.isclose(x, 0.1), axis=1)]
    evaluation = evaluate(scene, _result(tmp_path / "res", [(box.vertices, walls)]))
    assert _figures(evaluation.scene_space) == (1.0, 1.0, 1.0, 1.0)  # parity would fill nothing
    assert not evaluation.predictions[0].closed
    assert "scored as convex hull" in format_table(evaluation)


def test_evaluation_does_not_modify_inputs_and_serialises(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1, BOX_2])
    result = _result(tmp_path / "res", [_box(0.1, (0.06, 0.05, 0.05))])

    def snapshot():
        return {
            p: (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(tmp_path.rglob("*"))
            if p.is_file()
        }

    before = snapshot()
    evaluation = evaluate(scene, result)
    assert snapshot() == before
    data = json.loads(json.dumps(evaluation.to_dict()))
    assert data["scene_space"]["iou"] == pytest.approx(evaluation.scene_space.iou)
    assert data["ground_truth"][1]["matched_id"] is None
    table = format_table(evaluation)
    assert f"{evaluation.scene_space.iou:7.3f}" in table and "method test" in table


# --------------------------------------------------------------------------------------------
# Real YCB-Video scenes


@pytest.fixture(scope="module")
def ycbv(tmp_path_factory):
    root = ycbv_real_dir()
    if root is None:
        pytest.skip("shared ycbv_real data not found (set IPR_DATA or place ../shared/data)")
    out = tmp_path_factory.mktemp("gt")
    return {
        name: (root / name, write_ground_truth_result(root / name, out / name))
        for name in ("ycbv_0000", "ycbv_0001")
    }


@pytest.mark.parametrize("name", ["ycbv_0000", "ycbv_0001"])
def test_ground_truth_result_scores_one(ycbv, name):
    scene, result = ycbv[name]
    start = time.perf_counter()
    evaluation = evaluate(scene, result)
    elapsed = time.perf_counter() - start
    assert evaluation.visibility_source == "rendered"  # ycbv_real has no scene_gt_info.json
    assert evaluation.n_visible == evaluation.n_ground_truth == evaluation.n_predicted
    for space in (evaluation.scene_space, evaluation.object_space):
        assert min(_figures(space)) >= 0.99
    assert all(row.visible_px >= 1000 for row in evaluation.ground_truth)
    assert elapsed < 5.0  # about 0.4 s on the reference machine


def test_result_in_another_world_frame_is_scored_in_its_frame(ycbv, tmp_path):
    # The same objects expressed in the camera frame (world_from_camera = identity).
    scene, _ = ycbv["ycbv_0001"]
    poses = load_ground_truth(scene)[0]
    meshes = []
    for pose in poses:
        mesh = load_model(scene.parent / "models", pose.obj_id)
        mesh.apply_transform(pose.camera_from_model)
        meshes.append(mesh)
    evaluation = evaluate(scene, _result(tmp_path / "cam", meshes, world_from_camera=np.eye(4)))
    for space in (evaluation.scene_space, evaluation.object_space):
        assert min(_figures(space)) >= 0.99


def test_shifted_object_scores_the_independently_computed_value(ycbv, tmp_path):
    scene, gt_dir = ycbv["ycbv_0000"]
    gt = load_result(gt_dir)
    world_from_camera = gt.world_from_camera[0]
    poses = load_ground_truth(scene)[0]
    # Independent expectation: voxelise the models and the shifted model directly.
    truth = []
    for pose in poses:
        model = load_model(scene.parent / "models", pose.obj_id)
        model.apply_transform(world_from_camera @ pose.camera_from_model)
        truth.append(voxels.occupied_voxels(model))
    shifted = gt.objects[0].mesh.copy()
    shifted.apply_translation([0.01, 0.0, 0.0])
    moved = voxels.occupied_voxels(shifted)
    inter = np.intersect1d(moved, truth[0]).size
    iou_moved = inter / np.union1d(moved, truth[0]).size
    assert 0.3 < iou_moved < 0.9
    prediction = [moved, truth[1], truth[2]]
    union_pred, union_true = np.unique(np.concatenate(prediction)), np.unique(np.concatenate(truth))
    scene_iou = (
        np.intersect1d(union_pred, union_true).size / np.union1d(union_pred, union_true).size
    )

    meshes = [shifted] + [o.mesh for o in gt.objects[1:]]
    evaluation = evaluate(scene, _result(tmp_path / "res", meshes, world_from_camera))
    assert evaluation.scene_space.iou == pytest.approx(scene_iou, abs=2e-3)
    assert evaluation.object_space.iou == pytest.approx((iou_moved + 2.0) / 3.0, abs=2e-3)
    assert evaluation.ground_truth[0].scores.iou == pytest.approx(iou_moved, abs=2e-3)
    assert evaluation.ground_truth[0].scores.precision == pytest.approx(
        inter / moved.size, abs=2e-3
    )


def test_object_order_does_not_matter(ycbv, tmp_path):
    scene, gt_dir = ycbv["ycbv_0001"]
    gt = load_result(gt_dir)
    offsets = [(0.004, 0, 0), (0, 0.012, 0), (0.02, -0.01, 0), (0, 0, 0.008)]
    meshes = []
    for obj, offset in zip(gt.objects, offsets, strict=True):
        mesh = obj.mesh.copy()
        mesh.apply_translation(offset)
        meshes.append(mesh)
    result = _result(tmp_path / "res", meshes, gt.world_from_camera[0])
    permuted = tmp_path / "permuted"
    (permuted).mkdir()
    (permuted / "objects").symlink_to(result / "objects")
    document = json.loads((result / "result.json").read_text())
    document["objects"] = [document["objects"][i] for i in (2, 0, 3, 1)]
    (permuted / "result.json").write_text(json.dumps(document))

    first, second = evaluate(scene, result).to_dict(), evaluate(scene, permuted).to_dict()
    for data in (first, second):
        data.pop("result_path")
        data.pop("time_s")
    assert first == second
    assert 0.3 < first["object_space"]["iou"] < 0.95  # the offsets do change the figures


def test_pixels_without_a_depth_reading_show_the_front_most_model():
    from ipr_shapes.ground_truth import rendered_visible_pixel_counts

    camera_from_model = _translation([0.0, 0.0, 0.6])  # a 10 cm cube 0.6 m ahead
    counts = {}
    for reading in (0.0, 1.0, 0.3):  # none, behind the cube, in front of it
        depth = np.full((HEIGHT, WIDTH), reading, np.float32)
        frame = Frame(0, np.zeros((HEIGHT, WIDTH, 3), np.uint8), depth, K, np.eye(4))
        (counts[reading],) = rendered_visible_pixel_counts(frame, [camera_from_model], [_box(0.1)])
    assert counts[0.0] == counts[1.0] > 1000
    assert counts[0.3] == 0


def test_a_prediction_that_overlaps_no_ground_truth_is_not_its_match(tmp_path):
    scene = _box_scene(tmp_path, [BOX_1])
    evaluation = evaluate(scene, _result(tmp_path / "res", [_box(0.1, (0.6, 0.6, 0.05))]))
    # The one-to-one assignment pairs them (nothing else to pair), but they do not overlap.
    assert evaluation.n_matched == 0
    assert evaluation.ground_truth[0].matched_id is None
    assert evaluation.predictions[0].matched_gt_index is None
    assert _figures(evaluation.object_space) == (0.0, 0.0, 0.0, 0.0)
