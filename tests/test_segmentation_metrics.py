"""Segmentation metrics: hand-made label images give their exact expected scores, the scores do
not depend on label values, id consistency counts (object, later frame) pairs, and the
ground-truth masks agree with the generator's visibility counts and with real YCB-Video frames,
and BOP mask_visib/ files are read (and refused, naming the file, when malformed)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ipr_shapes.errors import SceneError
from ipr_shapes.rendering import Renderer
from ipr_shapes.scene import Frame, load_scene, load_visible_pixel_counts
from ipr_shapes.segmentation_metrics import (
    ground_truth_masks,
    id_consistency,
    id_consistency_counts,
    segmentation_scores,
)


def _two_objects() -> np.ndarray:
    """(20, 40) labels: object 1 = 10x10 (100 px), object 2 = 10x20 (200 px), rest background."""
    labels = np.zeros((20, 40), dtype=np.int32)
    labels[5:15, 0:10] = 1
    labels[5:15, 10:30] = 2
    return labels


def _blocky_labels(rng: np.random.Generator, count: int, shape=(48, 64)) -> np.ndarray:
    """Random labels 0..count on 8x8 blocks (so segments are a few hundred pixels)."""
    blocks = rng.integers(0, count + 1, size=(shape[0] // 8, shape[1] // 8))
    return np.kron(blocks, np.ones((8, 8), dtype=np.int64)).astype(np.int32)


def _figures(scores) -> list[tuple]:
    return [
        (row.gt_label, row.gt_px, row.segment_px, row.intersection_px, row.f_measure)
        for row in scores.objects
    ]


# --------------------------------------------------------------------------------------------
# segmentation_scores


def test_perfect_prediction_scores_one() -> None:
    truth = _two_objects()
    predicted = np.where(truth > 0, truth + 40, 0)  # other label values, same segments
    scores = segmentation_scores(predicted, truth)
    assert scores.n_visible == 2 and scores.n_segments == 2
    assert scores.precision == scores.recall == scores.f_measure == scores.share_f75 == 1.0
    assert [row.matched_label for row in scores.objects] == [41, 42]


def test_merged_objects_lose_precision_exactly() -> None:
    truth = _two_objects()
    predicted = (truth > 0).astype(np.int32) * 7  # one segment of 300 px covers both
    rows = segmentation_scores(predicted, truth).objects
    small, large = rows
    assert (small.matched_label, large.matched_label) == (7, 7)
    assert small.segment_px == large.segment_px == 300
    assert small.precision == pytest.approx(1 / 3) and small.recall == 1.0
    assert small.f_measure == pytest.approx(0.5)  # 2 * 100 / (300 + 100)
    assert large.precision == pytest.approx(2 / 3) and large.recall == 1.0
    assert large.f_measure == pytest.approx(0.8)  # 2 * 200 / (300 + 200)
    scores = segmentation_scores(predicted, truth)
    assert scores.share_f75 == 0.5
    assert scores.f_measure == pytest.approx(0.65)


def test_half_split_object_has_recall_one_half() -> None:
    truth = _two_objects()
    predicted = truth.copy()
    predicted[5:15, 20:30] = 3  # the right half of object 2 becomes its own segment
    large = segmentation_scores(predicted, truth).objects[1]
    assert large.recall == 0.5 and large.precision == 1.0
    assert large.f_measure == pytest.approx(2 / 3)
    assert large.matched_label == 2  # tie in F and intersection: the first (lower) label


def test_scores_do_not_depend_on_label_values() -> None:
    rng = np.random.default_rng(3)
    for _ in range(5):
        truth = _blocky_labels(rng, 5)
        predicted = _blocky_labels(rng, 6)
        reference = segmentation_scores(predicted, truth)
        permutation = np.concatenate([[0], rng.permutation(6) * 13 + 100])  # 0 stays 0
        relabelled = segmentation_scores(permutation[predicted], truth)
        assert _figures(relabelled) == _figures(reference)
        negative = segmentation_scores(np.where(predicted > 0, predicted, -1), truth)
        assert _figures(negative) == _figures(reference)  # any label <= 0 is "no segment"
        gt_permutation = np.concatenate([[0], rng.permutation(5) + 1])
        permuted_truth = segmentation_scores(predicted, gt_permutation[truth])
        assert sorted(row[1:] for row in _figures(permuted_truth)) == sorted(
            row[1:] for row in _figures(reference)
        )
        assert permuted_truth.f_measure == pytest.approx(reference.f_measure)


def test_matches_a_direct_per_pair_computation() -> None:
    rng = np.random.default_rng(7)
    truth = _blocky_labels(rng, 4)
    predicted = _blocky_labels(rng, 5)
    for row in segmentation_scores(predicted, truth, min_visible_px=1).objects:
        gt = truth == row.gt_label
        best = max(
            (2 * (gt & (predicted == s)).sum() / ((predicted == s).sum() + gt.sum()), s)
            for s in range(1, 6)
            if (predicted == s).any()
        )
        assert row.f_measure == pytest.approx(best[0])


def test_empty_prediction_scores_zero() -> None:
    truth = _two_objects()
    scores = segmentation_scores(np.zeros_like(truth), truth)
    assert scores.n_segments == 0 and scores.n_visible == 2
    assert all(row.f_measure == 0.0 and row.matched_label is None for row in scores.objects)
    assert scores.precision == scores.recall == scores.f_measure == scores.share_f75 == 0.0


def test_invisible_objects_are_left_out() -> None:
    truth = _two_objects()
    truth[0, 0:99] = 3  # 99 px: below the 100 px threshold
    scores = segmentation_scores(np.zeros_like(truth), truth)
    assert [row.gt_label for row in scores.objects] == [1, 2]  # 100 px exactly is visible
    assert (scores.n_visible, scores.n_invisible) == (2, 1)
    none = segmentation_scores(truth, np.zeros_like(truth))
    assert none.n_visible == 0 and math.isnan(none.f_measure)
    assert json.loads(json.dumps(none.to_dict()))["f_measure"] is None


def test_shape_mismatch_is_rejected() -> None:
    with pytest.raises(ValueError, match="same shape"):
        segmentation_scores(np.zeros((4, 4), int), np.zeros((4, 5), int))


# --------------------------------------------------------------------------------------------
# id_consistency


def test_id_consistency_counts_pairs() -> None:
    truth = _two_objects()
    frame0 = np.where(truth > 0, truth + 10, 0)  # object 1 -> id 11, object 2 -> id 12
    obj_ids = [[5, 9]] * 3
    assert id_consistency([frame0, frame0, frame0], [truth] * 3, obj_ids) == 1.0
    swapped = np.where(truth == 1, 12, frame0)  # object 1 takes object 2's id in frame 1 ...
    swapped = np.where(truth == 2, 11, swapped)  # ... and object 2 takes object 1's id
    renamed = np.where(truth == 1, 30, frame0)  # object 1 gets a new id
    assert id_consistency([frame0, renamed], [truth] * 2, obj_ids[:2]) == 0.5
    assert id_consistency([frame0, swapped], [truth] * 2, obj_ids[:2]) == 0.0
    counts = id_consistency_counts([frame0, frame0, renamed], [truth] * 3, obj_ids)
    assert (counts.consistent, counts.counted, counts.share) == (3, 4, 0.75)


def test_id_consistency_follows_obj_ids_not_positions() -> None:
    truth = _two_objects()
    prediction = np.where(truth > 0, truth + 10, 0)
    reordered = np.where(truth > 0, 3 - truth, 0)  # frame 1 lists the objects the other way
    result = id_consistency([prediction] * 2, [truth, reordered], [[5, 9], [9, 5]])
    assert result == 1.0


def test_id_consistency_lost_and_unfound_objects() -> None:
    truth = _two_objects()
    frame0 = np.where(truth == 2, 12, 0)  # object 1 is never found: not counted
    lost = np.zeros_like(truth)  # object 2 lost in frame 1: counted, not consistent
    counts = id_consistency_counts([frame0, lost], [truth] * 2, [[5, 9]] * 2)
    assert (counts.consistent, counts.counted) == (0, 1)
    hidden = np.where(truth == 2, 0, truth)  # object 2 not visible in frame 1: not counted
    counts = id_consistency_counts([frame0, lost], [truth, hidden], [[5, 9]] * 2)
    assert counts.counted == 0 and math.isnan(counts.share)
    merged = np.where(truth > 0, 12, 0)  # frame-0 F of object 2 with a 300 px segment = 0.8
    assert id_consistency([merged, merged], [truth] * 2, [[5, 9]] * 2) == 1.0


def test_lost_ids_say_what_happened_to_each_pair() -> None:
    truth = _two_objects()
    frame0 = np.where(truth > 0, truth + 10, 0)  # object 1 -> id 11, object 2 -> id 12
    swapped = np.where(truth == 1, 12, np.where(truth == 2, 11, 0))
    renamed = np.where(truth == 1, 30, frame0)  # object 1 under a new id, 11 nowhere
    gone = np.where(truth == 1, 0, frame0)  # object 1 has no segment in this frame
    sliver = renamed.copy()
    sliver[0, 0] = 11  # id 11 shown, but on no object's best segment
    counts = id_consistency_counts(
        [frame0, swapped, renamed, gone, sliver], [truth] * 5, [[5, 9]] * 5
    )
    assert (counts.consistent, counts.counted) == (3, 8)
    lost = {(x.frame, x.obj_id): x for x in counts.lost}
    assert sorted(lost) == [(1, 5), (1, 9), (2, 5), (3, 5), (4, 5)]
    assert (lost[1, 5].kind, lost[1, 5].label, lost[1, 5].frame0_label_holder) == (
        "other id",
        12,
        (9, 0),
    )
    assert (lost[2, 5].kind, lost[2, 5].label, lost[2, 5].frame0_label_shown) == (
        "new id",
        30,
        False,
    )
    assert (lost[3, 5].kind, lost[3, 5].label) == ("no segment", None)
    assert lost[4, 5].frame0_label_shown and lost[4, 5].frame0_label_holder is None
    assert all(x.frame0_label == {5: 11, 9: 12}[x.obj_id] for x in counts.lost)
    written = json.loads(json.dumps(counts.to_dict()))
    assert written["lost"][0]["frame0_label_holder"] == [9, 0]
    assert not any(x.piece_flip for x in counts.lost)


def test_a_lost_pair_whose_label_was_another_piece_of_the_object_is_a_piece_flip() -> None:
    truth = _two_objects()  # object 2: columns 10-29
    frame0 = np.where(truth == 1, 11, 0)
    frame0[5:15, 10:21] = 21  # object 2 in two pieces: 105 px (its best segment) ...
    frame0[5:15, 21:30] = 22  # ... and 90 px
    frame0[5:10, 10] = 11  # object 1's segment holds 5 px of object 2
    flipped = frame0.copy()
    flipped[5:15, 10:19] = 21  # the same two pieces, now 90 px ...
    flipped[5:15, 19:30] = 22  # ... and 110 px: the best segment is the other piece
    renamed = np.where(flipped == 22, 30, flipped)  # the larger piece under a new id
    stolen = np.where(truth == 1, 40, np.where(flipped == 22, 11, flipped))
    counts = id_consistency_counts([frame0, flipped, renamed, stolen], [truth] * 4, [[5, 9]] * 4)
    lost = {(x.frame, x.obj_id): x for x in counts.lost}
    assert sorted(lost) == [(1, 9), (2, 9), (3, 5), (3, 9)]
    assert (lost[1, 9].kind, lost[1, 9].label, lost[1, 9].piece_flip) == ("new id", 22, True)
    assert (lost[2, 9].label, lost[2, 9].piece_flip) == (30, False)
    # Label 11 held 5 px of object 2 in frame 0, but mostly object 1: another object's id.
    assert (lost[3, 9].kind, lost[3, 9].label, lost[3, 9].piece_flip) == ("other id", 11, False)


# --------------------------------------------------------------------------------------------
# ground_truth_masks


@pytest.mark.slow
def test_ground_truth_masks_match_generator_counts(tmp_path: Path) -> None:
    from ipr_shapes.synth import SynthConfig, generate_scene

    scene_path = generate_scene(
        tmp_path,
        kind="static",
        seed=1,
        arrangement="table",
        config=SynthConfig(width=320, height=240),
    )
    labels, obj_ids, visible_px = ground_truth_masks(scene_path, 0)
    assert labels.shape == (240, 320) and labels.dtype == np.int32
    gt = json.loads((scene_path / "scene_gt.json").read_text())["0"]
    assert obj_ids == [item["obj_id"] for item in gt]
    assert visible_px == np.bincount(labels.ravel(), minlength=len(gt) + 1)[1:].tolist()
    expected = load_visible_pixel_counts(scene_path)[0]
    assert sum(count >= 100 for count in expected) >= 3
    for ours, theirs in zip(visible_px, expected, strict=True):
        assert abs(ours - theirs) <= max(10, 0.03 * theirs), (visible_px, expected)

    frame = load_scene(scene_path).frames[0]
    with Renderer(320, 240) as renderer:
        again, _, _ = ground_truth_masks(scene_path, 0, renderer=renderer, frame=frame)
    assert np.array_equal(again, labels)
    truth = segmentation_scores(labels, labels)
    assert truth.share_f75 == 1.0


def test_ground_truth_masks_on_real_frames(shared_data: Path) -> None:
    scene_path = shared_data / "ycbv_real" / "ycbv_0000"
    labels, obj_ids, visible_px = ground_truth_masks(scene_path, 0)
    assert labels.shape == (480, 640)
    assert len(obj_ids) >= 3
    assert sum(count >= 1000 for count in visible_px) >= 3, visible_px
    observed = np.asarray(load_scene(scene_path).frames[0].depth_m)
    assert (observed[labels > 0] > 0).mean() > 0.8  # the masks lie on measured surfaces


@pytest.mark.slow
def test_ground_truth_masks_hide_objects_behind_generated_walls(tmp_path: Path) -> None:
    from ipr_shapes.synth import SynthConfig, generate_scene

    scene_path = generate_scene(
        tmp_path,
        kind="static",
        seed=4,
        arrangement="drawer",
        config=SynthConfig(width=320, height=240),
    )
    _, _, visible_px = ground_truth_masks(scene_path, 0)
    _, _, through_walls = ground_truth_masks(scene_path, 0, walls=False)
    expected = load_visible_pixel_counts(scene_path)[0]
    for ours, theirs in zip(visible_px, expected, strict=True):
        assert abs(ours - theirs) <= max(10, 0.03 * theirs), (visible_px, expected)
    assert sum(through_walls) > sum(visible_px)  # the drawer front hides some pixels


# --------------------------------------------------------------------------------------------
# ground_truth_masks from BOP mask_visib/ files


def _identity_pose(obj_id: int) -> dict:
    return {"obj_id": obj_id, "cam_R_m2c": np.eye(3).ravel().tolist(), "cam_t_m2c": [0, 0, 500]}


def _mask_scene(root: Path, masks: list[np.ndarray], *, info: bool = True) -> Path:
    """A 40x30 one-frame scene whose frame 0 lists one object per mask (obj_ids 1, 2, ...),
    with mask_visib/000000_KKKKKK.png (0/255) and, with ``info``, their px_count_visib; no
    models folder, so rendering would fail."""
    scene = root / "masks_scene"
    (scene / "depth").mkdir(parents=True)
    (scene / "mask_visib").mkdir()
    Image.fromarray(np.full((30, 40), 500, dtype=np.uint16)).save(scene / "depth" / "000000.png")
    camera = {"0": {"cam_K": [50.0, 0, 19.5, 0, 50.0, 14.5, 0, 0, 1], "depth_scale": 1.0}}
    (scene / "scene_camera.json").write_text(json.dumps(camera))
    gt = {"0": [_identity_pose(k + 1) for k in range(len(masks))]}
    (scene / "scene_gt.json").write_text(json.dumps(gt))
    if info:
        counts = [{"px_count_visib": int((m > 0).sum())} for m in masks]
        (scene / "scene_gt_info.json").write_text(json.dumps({"0": counts}))
    for position, mask in enumerate(masks):
        path = scene / "mask_visib" / f"000000_{position:06d}.png"
        Image.fromarray(np.where(mask > 0, 255, 0).astype(np.uint8)).save(path)
    return scene


def _three_masks() -> list[np.ndarray]:
    """(30, 40) masks: a 10x10 block, a 10x20 block overlapping it by 10x5, and an empty one."""
    first = np.zeros((30, 40), dtype=bool)
    first[5:15, 5:15] = True
    second = np.zeros((30, 40), dtype=bool)
    second[5:15, 10:30] = True
    return [first, second, np.zeros((30, 40), dtype=bool)]


def test_ground_truth_masks_read_bop_mask_files(tmp_path: Path) -> None:
    masks = _three_masks()
    scene = _mask_scene(tmp_path, masks)
    labels, obj_ids, visible_px = ground_truth_masks(scene, 0)
    assert labels.shape == (30, 40) and labels.dtype == np.int32
    assert obj_ids == [1, 2, 3]
    assert visible_px == [100, 150, 0]  # the shared 10x5 pixels go to the first listed object
    assert np.array_equal(labels[masks[0]], np.ones(100))
    assert np.array_equal(labels == 2, masks[1] & ~masks[0])
    assert not (labels[~(masks[0] | masks[1])]).any()
    scores = segmentation_scores(labels, labels)
    assert scores.n_visible == 2 and scores.n_invisible == 0  # the empty mask has no label

    frame = Frame(
        0, np.zeros((30, 40, 3), np.uint8), np.ones((30, 40), np.float32), np.eye(3), np.eye(4)
    )
    again, _, _ = ground_truth_masks(scene, 0, frame=frame)
    assert np.array_equal(again, labels)
    with pytest.raises(SceneError, match="obj_000001.ply"):  # mask_files=False renders models
        ground_truth_masks(scene, 0, mask_files=False)


def test_ground_truth_masks_read_mask_files_without_gt_info(tmp_path: Path) -> None:
    scene = _mask_scene(tmp_path, _three_masks(), info=False)
    _, _, visible_px = ground_truth_masks(scene, 0)
    assert visible_px == [100, 150, 0]


def _break_missing(scene: Path) -> str:
    (scene / "mask_visib" / "000000_000001.png").unlink()
    return "000000_000001.png: is missing"


def _break_extra(scene: Path) -> str:
    Image.fromarray(np.zeros((30, 40), np.uint8)).save(scene / "mask_visib" / "000000_000003.png")
    return "000000_000003.png: is the mask of object position 3, but scene_gt.json lists 3"


def _break_size(scene: Path) -> str:
    Image.fromarray(np.zeros((20, 40), np.uint8)).save(scene / "mask_visib" / "000000_000002.png")
    return "000000_000002.png: is 40x20 pixels, the frame 40x30"


def _break_channels(scene: Path) -> str:
    Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(
        scene / "mask_visib" / "000000_000002.png"
    )
    return "000000_000002.png: has 3 channels"


def _break_values(scene: Path) -> str:
    grey = np.zeros((30, 40), np.uint8)
    grey[0, 0] = 128
    Image.fromarray(grey).save(scene / "mask_visib" / "000000_000002.png")
    return r"000000_000002.png: is not a binary mask \(values 0, 128\)"


def _break_not_png(scene: Path) -> str:
    (scene / "mask_visib" / "000000_000000.png").write_text("not an image")
    return "000000_000000.png: is not a readable image"


def _break_jpeg(scene: Path) -> str:
    path = scene / "mask_visib" / "000000_000000.png"
    Image.fromarray(np.zeros((30, 40), np.uint8)).save(path, format="JPEG")
    return "000000_000000.png: is a JPEG image, not a PNG"


def _break_count(scene: Path) -> str:
    info_path = scene / "scene_gt_info.json"
    info = json.loads(info_path.read_text())
    info["0"][1]["px_count_visib"] = 199
    info_path.write_text(json.dumps(info))
    return "000000_000001.png: has 200 visible pixels, scene_gt_info.json says px_count_visib 199"


def _break_name(scene: Path) -> str:
    Image.fromarray(np.zeros((30, 40), np.uint8)).save(scene / "mask_visib" / "000000_a.png")
    return "000000_a.png: is not named FFFFFF_KKKKKK.png"


@pytest.mark.parametrize(
    "breaks",
    [
        _break_missing,
        _break_extra,
        _break_size,
        _break_channels,
        _break_values,
        _break_not_png,
        _break_jpeg,
        _break_count,
        _break_name,
    ],
)
def test_malformed_mask_files_are_refused_naming_the_file(tmp_path: Path, breaks) -> None:
    scene = _mask_scene(tmp_path, _three_masks())
    expected = breaks(scene)
    with pytest.raises(SceneError, match=expected):
        ground_truth_masks(scene, 0)


def test_ground_truth_masks_of_bins_real_are_its_mask_files() -> None:
    from ipr_shapes.data import bins_real_dir

    root = bins_real_dir()
    if root is None:
        pytest.skip("bins_real data (../shared/data/bins_real or $IPR_DATA) is absent")
    scene = root / "bins_000"
    labels, obj_ids, visible_px = ground_truth_masks(scene, 0)
    gt = json.loads((scene / "scene_gt.json").read_text())["0"]
    assert obj_ids == [item["obj_id"] for item in gt] and len(obj_ids) >= 11
    assert visible_px == load_visible_pixel_counts(scene)[0]  # the masks do not overlap here
    for position in range(len(gt)):
        with Image.open(scene / "mask_visib" / f"000000_{position:06d}.png") as image:
            assert np.array_equal(labels == position + 1, np.asarray(image) > 0)
    # The files and the masks rendered from the box models with the same rule agree.
    rendered, _, _ = ground_truth_masks(scene, 0, mask_files=False)
    scores = segmentation_scores(rendered, labels)
    assert scores.n_visible == len(gt)
    assert min(row.f_measure for row in scores.objects) > 0.99
