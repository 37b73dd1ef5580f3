"""Shape-reconstruction metrics of the contract (``SCENE_FORMAT.md``, "Metrics").

Occupancy is compared on a world-frame voxel grid (default pitch 5 mm, centres at (n + 1/2) p):
a voxel is occupied by a mesh when its centre is inside it (``ipr_shapes.voxels``; a mesh that is not
closed is scored as its convex hull).

- Ground truth: each BOP model (mm -> m) at its frame-0 pose, placed in the *result's* world
  frame: ``world_from_model = result.world_from_camera[0] @ camera_from_model``, so a result
  that chose another world frame is still scored correctly.
- Visible objects: ``px_count_visib >= min_visible_px`` in frame 0 from ``scene_gt_info.json``,
  or, without that file, counted by rendering every ground-truth model from frame 0's camera: a
  pixel shows an object when the object is the front-most model there and its rendered depth is
  at most the observed depth + 15 mm (or the observed depth is missing) — the BOP convention.
  Objects that are not visible are left out of both spaces.
- Scene space: the union of all predicted objects against the union of the visible
  ground-truth objects.
- Object space: predictions and visible ground-truth objects are matched one-to-one by the
  Hungarian assignment maximising the summed IoU (pairs that do not overlap are not matches);
  each visible ground-truth object scores the IoU, precision, recall and F1 of its match, 0 when
  unmatched; the figures are averaged over the visible ground-truth objects.

Ratios with a zero denominator (``scores``): when prediction and ground truth are both empty
every figure is 1 (nothing to find, nothing claimed); otherwise 0/0 counts as 0. F1 is the
harmonic mean of precision and recall (0 when both are 0). With no visible ground-truth object
the object-space figures follow the same rule (1 when nothing is predicted, else 0).

Only evaluation reads ground truth; inputs are never modified.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.ground_truth import frame0_ground_truth, visible_pixel_counts
from ipr_shapes.result import Result, load_result

DEFAULT_MIN_VISIBLE_PX = 100


@dataclass(frozen=True)
class Scores:
    """IoU, precision, recall and F1 of a prediction against a ground truth, each in [0, 1]."""

    iou: float
    precision: float
    recall: float
    f1: float


ZERO = Scores(0.0, 0.0, 0.0, 0.0)


def scores(predicted: int, ground_truth: int, intersection: int) -> Scores:
    """Scores from voxel counts |P|, |G| and |P ∩ G| (zero-denominator rules in the module doc)."""
    if predicted == 0 and ground_truth == 0:
        return Scores(1.0, 1.0, 1.0, 1.0)
    union = predicted + ground_truth - intersection
    iou = intersection / union if union else 0.0
    precision = intersection / predicted if predicted else 0.0
    recall = intersection / ground_truth if ground_truth else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return Scores(iou, precision, recall, f1)


def mean_scores(rows: list[Scores], n_predicted: int) -> Scores:
    """Average of per-object scores; with no object: 1 when nothing is predicted, else 0."""
    if not rows:
        return Scores(1.0, 1.0, 1.0, 1.0) if n_predicted == 0 else ZERO
    values = np.array([[r.iou, r.precision, r.recall, r.f1] for r in rows]).mean(axis=0)
    return Scores(*(float(v) for v in values))


@dataclass(frozen=True)
class GroundTruthRow:
    """One ground-truth object of frame 0 (``scene_gt.json`` order ``gt_index``).

    ``scores`` and ``matched_id`` are None for an object that is not visible (excluded);
    ``matched_id`` is also None when no prediction matched it (its scores are then 0).
    Voxel counts are at the evaluation pitch.
    """

    gt_index: int
    obj_id: int
    visible_px: int
    visible: bool
    voxels: int
    matched_id: int | None
    scores: Scores | None


@dataclass(frozen=True)
class PredictionRow:
    """One predicted object: its result id, voxel count, whether its mesh was closed (else it
    was scored as its convex hull), and the ``gt_index`` it matched (None if unmatched)."""

    id: int
    voxels: int
    closed: bool
    matched_gt_index: int | None


@dataclass(frozen=True)
class Evaluation:
    """Metrics of one result on one scene (see the module doc for the definitions)."""

    scene_path: str
    result_path: str
    method: str
    voxel_size_m: float
    min_visible_px: int
    visibility_source: str  # "scene_gt_info" or "rendered"
    scene_space: Scores
    object_space: Scores
    ground_truth: tuple[GroundTruthRow, ...]
    predictions: tuple[PredictionRow, ...]
    n_ground_truth: int
    n_visible: int
    n_predicted: int
    n_matched: int
    time_s: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict (plain floats, ints, strings, None)."""
        return asdict(self)


# --------------------------------------------------------------------------------------------
# Ground truth and visibility


# --------------------------------------------------------------------------------------------
# Evaluation


def evaluate(
    scene_path: Path | str,
    result_path: Path | str | Result,
    models_dir: Path | str | None = None,
    voxel_size_m: float = voxels.DEFAULT_PITCH_M,
    min_visible_px: int = DEFAULT_MIN_VISIBLE_PX,
) -> Evaluation:
    """Score a result (directory or loaded ``Result``) against a scene's frame-0 ground truth.

    ``models_dir`` holds the BOP models (default ``<scene>/../models``); ``voxel_size_m`` is the
    grid pitch in metres; ``min_visible_px`` the visibility threshold in frame-0 pixels.
    Raises SceneError/ResultError (with file and fix) on invalid inputs.
    """
    start = time.perf_counter()
    if voxel_size_m <= 0:
        raise ValueError(f"voxel_size_m must be positive, got {voxel_size_m}")
    scene_path = Path(scene_path)
    result = result_path if isinstance(result_path, Result) else load_result(result_path)
    reference = min(result.world_from_camera)  # the result's first frame: 0 in our scenes
    poses, models, _ = frame0_ground_truth(scene_path, models_dir, reference)
    counts, source = visible_pixel_counts(scene_path, poses, models, reference)
    visible = counts >= min_visible_px

    world_from_camera = result.world_from_camera[reference]
    gt_keys: dict[int, np.ndarray] = {}
    for index, (pose, model) in enumerate(zip(poses, models, strict=True)):
        if visible[index]:
            gt_keys[index] = voxels.occupied_voxels(
                model, voxel_size_m, world_from_camera @ pose.camera_from_model
            )

    predicted = sorted(result.objects, key=lambda obj: obj.id)  # order-independent matching
    pred_keys, closed = [], []
    for obj in predicted:
        vertices, faces, is_closed = voxels.closed_or_hull(obj.load_mesh())
        pred_keys.append(voxels.scanline_voxels(vertices, faces, voxel_size_m))
        closed.append(is_closed)

    # Scene space.
    all_pred = voxels.union(*pred_keys)
    all_gt = voxels.union(*gt_keys.values())
    scene_space = scores(all_pred.size, all_gt.size, voxels.intersection_count(all_pred, all_gt))

    # Object space: Hungarian assignment on IoU.
    gt_indices = sorted(gt_keys)
    intersections = np.array(
        [[voxels.intersection_count(p, gt_keys[g]) for g in gt_indices] for p in pred_keys],
        dtype=np.int64,
    ).reshape(len(pred_keys), len(gt_indices))
    pred_sizes = np.array([k.size for k in pred_keys], dtype=np.int64)
    gt_sizes = np.array([gt_keys[g].size for g in gt_indices], dtype=np.int64)
    unions = pred_sizes[:, None] + gt_sizes[None, :] - intersections
    iou = np.divide(intersections, unions, out=np.zeros(unions.shape), where=unions > 0)
    match_of_gt: dict[int, int] = {}  # gt column -> prediction row
    if iou.size:
        from scipy.optimize import linear_sum_assignment

        rows, cols = linear_sum_assignment(iou, maximize=True)
        match_of_gt = {
            int(c): int(r) for r, c in zip(rows, cols, strict=True) if intersections[r, c] > 0
        }

    gt_rows, object_scores = [], []
    column_of_gt = {g: c for c, g in enumerate(gt_indices)}
    for index, pose in enumerate(poses):
        if not visible[index]:
            gt_rows.append(
                GroundTruthRow(index, pose.obj_id, int(counts[index]), False, 0, None, None)
            )
            continue
        column = column_of_gt[index]
        row = match_of_gt.get(column)
        if row is None:
            score, matched = ZERO, None
        else:
            score = scores(
                int(pred_sizes[row]), int(gt_sizes[column]), int(intersections[row, column])
            )
            matched = predicted[row].id
        object_scores.append(score)
        gt_rows.append(
            GroundTruthRow(
                index, pose.obj_id, int(counts[index]), True, int(gt_sizes[column]), matched, score
            )
        )
    gt_of_pred = {row: gt_indices[column] for column, row in match_of_gt.items()}
    prediction_rows = tuple(
        PredictionRow(obj.id, int(pred_sizes[row]), closed[row], gt_of_pred.get(row))
        for row, obj in enumerate(predicted)
    )

    return Evaluation(
        scene_path=str(scene_path),
        result_path=str(result.path),
        method=result.method,
        voxel_size_m=float(voxel_size_m),
        min_visible_px=int(min_visible_px),
        visibility_source=source,
        scene_space=scene_space,
        object_space=mean_scores(object_scores, len(predicted)),
        ground_truth=tuple(gt_rows),
        predictions=prediction_rows,
        n_ground_truth=len(poses),
        n_visible=int(visible.sum()),
        n_predicted=len(predicted),
        n_matched=len(match_of_gt),
        time_s=time.perf_counter() - start,
    )


# --------------------------------------------------------------------------------------------
# Presentation


def format_table(evaluation: Evaluation) -> str:
    """Plain-text report: the two spaces, then one line per ground-truth object."""

    def figures(s: Scores | None) -> str:
        if s is None:
            return f"{'-':>7}{'-':>7}{'-':>7}{'-':>7}"
        return f"{s.iou:7.3f}{s.precision:7.3f}{s.recall:7.3f}{s.f1:7.3f}"

    e = evaluation
    lines = [
        f"scene {e.scene_path}",
        f"result {e.result_path} (method {e.method})",
        f"voxels {e.voxel_size_m * 1000:g} mm; visible objects {e.n_visible}/{e.n_ground_truth} "
        f"(>= {e.min_visible_px} px, {e.visibility_source}); predicted {e.n_predicted}, "
        f"matched {e.n_matched}",
        "",
        f"{'space':<10}{'IoU':>7}{'prec':>7}{'recall':>7}{'F1':>7}",
        f"{'scene':<10}{figures(e.scene_space)}",
        f"{'object':<10}{figures(e.object_space)}",
        "",
        f"{'obj_id':>6}{'vis_px':>8}{'voxels':>8}{'match':>7}{'IoU':>7}{'prec':>7}{'recall':>7}"
        f"{'F1':>7}",
    ]
    for row in e.ground_truth:
        match = "-" if row.matched_id is None else str(row.matched_id)
        if not row.visible:
            match = "hidden"
        lines.append(
            f"{row.obj_id:>6}{row.visible_px:>8}{row.voxels:>8}{match:>7}{figures(row.scores)}"
        )
    hulls = [p.id for p in e.predictions if not p.closed]
    unmatched = [p.id for p in e.predictions if p.matched_gt_index is None]
    if hulls:
        lines.append(f"scored as convex hull (mesh not closed): ids {hulls}")
    if unmatched:
        lines.append(f"unmatched predictions: ids {unmatched}")
    return "\n".join(lines)
