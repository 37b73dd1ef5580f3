"""Ground truth of a scene, for evaluation only (inference never reads it): frame-0 poses and
models, which objects are visible (the BOP rule), and the oracle result that places the models.

Visible objects: ``px_count_visib`` of ``scene_gt_info.json`` when present, else counted by
rendering every ground-truth model from frame 0's camera: a pixel shows an object when the
object is the front-most model there and its rendered depth is at most the observed depth + 15
mm (or the observed depth is missing).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes.atomic import check_output_location
from ipr_shapes.errors import SceneError
from ipr_shapes.result import GROUND_TRUTH_METHOD, write_result
from ipr_shapes.scene import (
    Frame,
    ObjectPose,
    Scene,
    default_models_dir,
    load_ground_truth,
    load_model,
    load_scene,
    load_visible_pixel_counts,
)

#: BOP visibility tolerance: a rendered surface up to this far (m) behind the observed depth is
#: still seen.
VISIBILITY_TOLERANCE_M = 0.015


def frame0_ground_truth(
    scene_path: Path | str, models_dir: Path | str | None = None, frame: int = 0
) -> tuple[list[ObjectPose], list[Any], Path]:
    """Frame-0 ground-truth poses (camera from model, m), the model mesh of each (trimesh,
    metres, model frame; one shared object per obj_id) and the models folder used.

    ``models_dir`` defaults to the contract's ``<scene>/../models``; ``frame`` is the id of the
    reference frame (the first frame of the result, 0 in the project's own scenes).
    """
    scene_path = Path(scene_path)
    ground_truth = load_ground_truth(scene_path)
    if frame not in ground_truth:
        raise SceneError(
            scene_path / "scene_gt.json",
            f"has no frame {frame} (the result's first frame)",
            f'give the frame-{frame} object poses under key "{frame}"',
        )
    poses = ground_truth[frame]
    folder = Path(models_dir) if models_dir is not None else default_models_dir(scene_path)
    cache: dict[int, Any] = {}
    for pose in poses:
        if pose.obj_id not in cache:
            cache[pose.obj_id] = load_model(folder, pose.obj_id)
    return poses, [cache[pose.obj_id] for pose in poses], folder


def rendered_visible_pixel_counts(
    frame: Frame,
    camera_from_model: list[np.ndarray],
    models: list[Any],
    *,
    tolerance_m: float = VISIBILITY_TOLERANCE_M,
) -> np.ndarray:
    """Pixels (N,) int64 of ``frame`` that show each model (BOP rule, module doc).

    Models (metres, model frame) are rendered together from the frame's camera with poses
    ``camera_from_model`` (4x4, metres); a pixel counts for the front-most model when its
    rendered depth is at most the observed depth + ``tolerance_m`` or there is no reading.
    """
    from ipr_shapes.rendering import render_depth_and_ids

    height, width = frame.shape
    depth, index = render_depth_and_ids(
        models, camera_from_model, frame.K, width, height, np.eye(4)
    )
    observed = frame.depth_m
    consistent = (observed <= 0) | (depth <= observed + tolerance_m)
    shown = index[(index >= 0) & consistent]
    return np.bincount(shown, minlength=len(models)).astype(np.int64)


def visible_pixel_counts(
    scene: Scene | Path | str, poses: list[ObjectPose], models: list[Any], frame: int = 0
) -> tuple[np.ndarray, str]:
    """Frame-0 visible pixels of each ground-truth object and where they come from.

    Uses ``px_count_visib`` of ``scene_gt_info.json`` when the scene has it (source
    ``"scene_gt_info"``), else renders the models (``"rendered"``; needs the scene's frame 0,
    loaded when a path is given).
    """
    path = scene.path if isinstance(scene, Scene) else Path(scene)
    counts = load_visible_pixel_counts(path)
    if counts is not None:
        if frame not in counts or len(counts[frame]) != len(poses):
            raise SceneError(
                path / "scene_gt_info.json",
                f"frame {frame} must list one entry per object of scene_gt.json",
                "regenerate scene_gt_info.json from scene_gt.json",
            )
        return np.asarray(counts[frame], dtype=np.int64), "scene_gt_info"
    loaded = scene if isinstance(scene, Scene) else load_scene(path, frames=[frame])
    (reference,) = [f for f in loaded.frames if f.index == frame] or [loaded.frames[0]]
    counts_rendered = rendered_visible_pixel_counts(
        reference, [pose.camera_from_model for pose in poses], models
    )
    return counts_rendered, "rendered"


def write_ground_truth_result(
    scene_path: Path | str,
    out_dir: Path | str,
    models_dir: Path | str | None = None,
    overwrite: bool = False,
    *,
    visible_only: bool = True,
    min_visible_px: int = 100,
) -> Path:
    """Write the oracle result of a scene: its ground-truth models at their frame-0 poses.

    The world frame is the one ``ipr_shapes.scene.load_scene`` builds for frame 0 (camera poses, or the
    support plane); each model (BOP, mm -> m) is placed with ``world_from_camera[0] @
    camera_from_model`` and given probability 1, method ``"ground-truth"``. With
    ``visible_only`` (default) only objects visible in frame 0 by the metrics' rule
    (``visible_pixel_counts`` >= ``min_visible_px``) are written, so that the oracle
    scores 1 in both spaces. ``extra["ground_truth"]`` records the scene, the BOP ``obj_id`` of
    each written object (in object order) and the excluded ones.
    """
    check_output_location(out_dir, [scene_path], overwrite=overwrite)
    scene = load_scene(scene_path)
    poses, models, models_dir = frame0_ground_truth(scene_path, models_dir)
    world_from_camera = scene.frames[0].world_from_camera
    keep = [True] * len(poses)
    if visible_only:
        counts, _ = visible_pixel_counts(scene, poses, models)
        keep = [int(c) >= min_visible_px for c in counts]
    objects = []
    for pose, mesh, kept in zip(poses, models, keep, strict=True):
        if kept:
            placed = mesh.copy()
            placed.apply_transform(world_from_camera @ pose.camera_from_model)
            objects.append((placed, []))
    extra = {
        "ground_truth": {
            "scene": str(Path(scene_path).resolve()),
            "models_dir": str(Path(models_dir).resolve()),
            "obj_ids": [pose.obj_id for pose, kept in zip(poses, keep, strict=True) if kept],
            "excluded_obj_ids": [
                pose.obj_id for pose, kept in zip(poses, keep, strict=True) if not kept
            ],
        }
    }
    return write_result(
        out_dir,
        GROUND_TRUTH_METHOD,
        {scene.frames[0].index: world_from_camera},
        objects,
        {"total": 0.0},
        extra,
        overwrite=overwrite,
    )
