"""Segmentation metrics: ground-truth object masks of a frame, per-object overlap scores of a
predicted label image, and id consistency of tracked labels across frames.

Ground-truth masks (``ground_truth_masks``): every ground-truth model of the frame
(``scene_gt.json``; BOP models, mm -> m) is rendered with its camera-from-model pose from the
frame's own camera (world = camera frame: the objects need no camera pose). A pixel belongs to
object ``k`` when model ``k`` is the front-most model there **and** it is consistent with the
observed depth — rendered depth <= observed depth + 15 mm, or no depth reading — the BOP
visibility rule (also used by ``ipr_shapes.metrics``). Pixels where something that is not a
ground-truth object (a wall, a drawer front, the robot) hides the model by more than 15 mm
therefore do not count, and pixels without a depth reading do. Scenes made by ``ipr_shapes.synth`` list
their container/drawer walls in ``synth.json``; those walls are rendered too and hide what lies
behind them exactly (a 1 cm wall is thinner than the tolerance, so the depth test alone would
let objects pressed against it show through). The masks then agree closely with the
generator's own ``px_count_visib``; labels are the object's position in the frame's
``scene_gt.json`` list plus one; 0 is background.

Scenes that come with BOP visible masks (``mask_visib/FFFFFF_KKKKKK.png``: frame id ``F``, then
the position ``K`` of the object in ``scene_gt.json[F]``, non-zero = visible) are not rendered:
when a frame has any such file, its masks are read instead (``read_mask_files``) and must be
complete and well formed — one single-channel PNG of the frame's size per listed object, values
0 and 255 (or 0 and 1), no file for an object the frame does not list, and, when
``scene_gt_info.json`` gives the frame's ``px_count_visib``, exactly that many non-zero pixels
per mask — else a ``SceneError`` names the file. BOP masks may overlap (each object's mask is
tested against the sensor depth alone): a pixel in several masks goes to the first listed of
them. The visibility threshold below then applies to the masks' pixel counts, which equal
``px_count_visib`` where the masks do not overlap.

Overlap scores (``segmentation_scores``), the OSD/OCID object-overlap convention: for each
*visible* ground-truth object G (at least ``min_visible_px`` pixels in the ground-truth label
image), among the predicted segments S (labels > 0) the one with the best F-measure is chosen,

    precision = |S ∩ G| / |S|,  recall = |S ∩ G| / |G|,  F = 2 P R / (P + R) = 2 |S ∩ G| / (|S| + |G|);

ties in F are broken by the larger intersection (so the scores never depend on the label
values). The choice is *not* one-to-one: a segment that merges two objects is the best segment of
both, and both lose precision; an object split into several segments loses recall. Pixels of a
segment that lie on the background or on invisible objects count in |S|. An object that no
segment overlaps scores 0 (matched label None). Means are over the visible objects, and
``share_f75`` is the share of visible objects with F >= 0.75; with no visible object the means
and the share are nan (``to_dict`` writes None).

Id consistency (``id_consistency``): ground-truth objects are identified across frames by their
``obj_id`` (the k-th occurrence of an ``obj_id`` in a frame pairs with its k-th occurrence in the
other frames). A pair (object o, later frame t >= 1) is *counted* when o is visible in frame 0
and in frame t and o's best segment in frame 0 has F >= 0.5 (the object was found, so it has a
predicted id to keep). The pair is *consistent* when o's best segment in frame t also has
F >= 0.5 and carries the same predicted label as in frame 0. Id consistency = consistent pairs /
counted pairs (nan when nothing is counted). Losing an object in frame t (F < 0.5) therefore
counts as failing to keep its id.

Inputs are never modified; label images are (H, W) integer arrays.
"""

from __future__ import annotations

import functools
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from ipr_shapes.camera import invert_transform, make_transform
from ipr_shapes.errors import SceneError
from ipr_shapes.scene import (
    Frame,
    default_models_dir,
    load_ground_truth,
    load_model,
    load_visible_pixel_counts,
    read_json,
)

#: BOP visibility tolerance (m): a rendered surface up to this far behind the observed depth is
#: still seen (the same value as ``ipr_shapes.ground_truth.VISIBILITY_TOLERANCE_M``).
VISIBILITY_TOLERANCE_M = 0.015
#: Ground-truth pixels an object needs to be scored (the contract's visibility threshold).
DEFAULT_MIN_VISIBLE_PX = 100
#: F-measure from which an object counts as well segmented (OSD/OCID convention).
F_THRESHOLD = 0.75
#: F-measure a segment needs to be an object's predicted id in ``id_consistency``.
ID_MATCH_MIN_F = 0.5


# --------------------------------------------------------------------------------------------
# Ground-truth masks


@functools.lru_cache(maxsize=256)
def _model_arrays(models_dir: str, obj_id: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 metres and faces (F, 3) int64 of a BOP model, loaded once."""
    mesh = load_model(models_dir, obj_id)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertices.setflags(write=False)
    faces.setflags(write=False)
    return vertices, faces


@dataclass(frozen=True, eq=False)
class _PosedModels:
    """A compiled MuJoCo model of BOP models and occluding boxes on mocap bodies (models first,
    then boxes), seen by a fixed camera at the world origin (the frame's camera): built once per
    (models, boxes, intrinsics, size) and re-posed for every frame. ``object_of_geom`` (ngeom,)
    int32 maps geoms to object positions, -1 for the boxes."""

    model: Any
    object_of_geom: np.ndarray


@functools.lru_cache(maxsize=4)
def _posed_models(
    models_dir: str,
    obj_ids: tuple[int, ...],
    box_half_sizes: tuple[tuple[float, float, float], ...],
    K_bytes: bytes,
    width: int,
    height: int,
) -> _PosedModels:
    import mujoco

    from ipr_shapes.rendering import (
        PinholeCamera,
        add_pinhole_camera,
        add_visual_mesh,
        configure_visual,
    )

    K = np.frombuffer(K_bytes, dtype=np.float64).reshape(3, 3)
    spec = mujoco.MjSpec()
    spec.modelname = "ipr_ground_truth_masks"
    configure_visual(spec, width, height)
    object_of_geom = []
    for position, obj_id in enumerate(obj_ids):
        vertices, faces = _model_arrays(models_dir, obj_id)
        body = spec.worldbody.add_body(name=f"object_{position}", mocap=True)
        if add_visual_mesh(spec, f"object_{position}", vertices, faces, body=body) is not None:
            object_of_geom.append(position)
    for number, half_size in enumerate(box_half_sizes):
        body = spec.worldbody.add_body(name=f"occluder_{number}", mocap=True)
        body.add_geom(
            name=f"occluder_{number}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(half_size),
            contype=0,
            conaffinity=0,
        )
        object_of_geom.append(-1)
    add_pinhole_camera(spec, PinholeCamera(K, width, height, np.eye(4)))
    return _PosedModels(spec.compile(), np.asarray(object_of_geom, dtype=np.int32))


def _render_posed_models(
    models_dir: str,
    obj_ids: list[int],
    camera_from_model: list[np.ndarray],
    boxes: list[tuple[np.ndarray, np.ndarray]],
    K: np.ndarray,
    width: int,
    height: int,
    renderer: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """Depth (H, W) float32 metres (0 = nothing) and front-most object position (H, W) int32
    (-1 = none or an occluding box) of the models posed in the camera frame
    (``camera_from_model`` (4, 4), metres) and the ``boxes`` (half sizes (3,), camera-from-box
    (4, 4)); the compiled model is reused across frames."""
    import mujoco

    from ipr_shapes.rendering import CAMERA_NAME, Renderer

    posed = _posed_models(
        models_dir,
        tuple(obj_ids),
        tuple(tuple(float(v) for v in half) for half, _ in boxes),
        np.ascontiguousarray(K, np.float64).tobytes(),
        width,
        height,
    )
    data = mujoco.MjData(posed.model)
    poses = [*camera_from_model, *(pose for _, pose in boxes)]
    for body, transform in enumerate(poses):
        data.mocap_pos[body] = transform[:3, 3]
        rotation = np.ascontiguousarray(transform[:3, :3], dtype=np.float64).ravel()
        mujoco.mju_mat2Quat(data.mocap_quat[body], rotation)
    mujoco.mj_kinematics(posed.model, data)
    mujoco.mj_camlight(posed.model, data)
    if renderer is not None and (renderer.width, renderer.height) != (width, height):
        raise ValueError(
            f"renderer is {renderer.width}x{renderer.height}, image is {width}x{height}"
        )
    active = Renderer(width, height) if renderer is None else renderer
    try:
        images = active.render(posed.model, data, CAMERA_NAME)
    finally:
        if renderer is None:
            active.close()
    lookup = np.append(posed.object_of_geom, -1).astype(np.int32)  # geom -1 -> -1
    return images.depth_m, lookup[images.geom_id]


def synth_walls(scene_path: Path | str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Walls of a scene made by ``ipr_shapes.synth`` (container and drawer arrangements), read from its
    ``synth.json``: (half sizes (3,) m, world-from-box (4, 4)) per wall, axis-aligned boxes in
    the scene's world frame; an empty list for other scenes."""
    path = Path(scene_path) / "synth.json"
    if not path.is_file():
        return []
    walls = read_json(path, "synth.json").get("support", {}).get("walls", [])
    result = []
    for wall in walls:
        pose = np.eye(4)
        pose[:3, 3] = np.asarray(wall["centre_m"], dtype=np.float64)
        result.append((np.asarray(wall["half_size_m"], dtype=np.float64), pose))
    return result


def _read_frame(
    scene_path: Path, frame_index: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Intrinsics (3, 3), observed depth (H, W) float32 metres and world-from-camera (4, 4)
    (None when the files give no camera pose) of one frame, read from the scene files without
    loading the other frames."""
    camera_path = scene_path / "scene_camera.json"
    cameras = read_json(camera_path, "scene_camera.json")
    entry = cameras.get(str(frame_index)) if isinstance(cameras, dict) else None
    if not isinstance(entry, dict) or "cam_K" not in entry or "depth_scale" not in entry:
        raise SceneError(
            camera_path, f"frame {frame_index} has no cam_K/depth_scale entry", "add the frame"
        )
    K = np.asarray(entry["cam_K"], dtype=np.float64).reshape(3, 3)
    world_from_camera = None
    if "cam_R_w2c" in entry and "cam_t_w2c" in entry:
        camera_from_world = make_transform(
            np.asarray(entry["cam_R_w2c"], dtype=np.float64).reshape(3, 3),
            np.asarray(entry["cam_t_w2c"], dtype=np.float64) / 1000.0,
        )
        world_from_camera = invert_transform(camera_from_world)
    depth_path = scene_path / "depth" / f"{frame_index:06d}.png"
    if not depth_path.is_file():
        raise SceneError(depth_path, "depth image is missing", "add the frame's depth PNG")
    with Image.open(depth_path) as image:
        units = np.asarray(image)
    depth_m = units.astype(np.float32) * np.float32(float(entry["depth_scale"]) / 1000.0)
    return K, depth_m, world_from_camera


def mask_file_paths(scene_path: Path | str, frame_index: int) -> dict[int, Path]:
    """The BOP visible-mask files of one frame, ``<scene>/mask_visib/FFFFFF_KKKKKK.png``, by
    object position ``K`` (module doc); empty when the scene has none for the frame."""
    folder = Path(scene_path) / "mask_visib"
    if not folder.is_dir():
        return {}
    prefix = f"{frame_index:06d}_"
    found = {}
    for path in folder.glob(f"{prefix}*.png"):
        position = path.stem[len(prefix) :]
        if not position.isdigit():
            raise SceneError(
                path,
                "is not named FFFFFF_KKKKKK.png (frame id, then the object's position in "
                "scene_gt.json)",
                "rename or remove it",
            )
        found[int(position)] = path
    return dict(sorted(found.items()))


def _frame_shape(scene_path: Path, frame_index: int) -> tuple[int, int]:
    """(H, W) of a frame from its depth image's header (the pixels are not read)."""
    depth_path = scene_path / "depth" / f"{frame_index:06d}.png"
    if not depth_path.is_file():
        raise SceneError(depth_path, "depth image is missing", "add the frame's depth PNG")
    with Image.open(depth_path) as image:
        width, height = image.size
    return height, width


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """One BOP mask as (H, W) bool; SceneError naming the file when it is not a binary,
    single-channel PNG of ``shape``."""
    fix = "write a single-channel PNG of the frame's size, 255 where the object is visible"
    try:
        with Image.open(path) as image:
            image.load()
            fmt, array = image.format, np.asarray(image)
    except (OSError, ValueError, SyntaxError) as error:
        raise SceneError(path, f"is not a readable image ({error})", fix) from None
    if fmt != "PNG":
        raise SceneError(path, f"is a {fmt} image, not a PNG", fix)
    if array.ndim != 2:
        raise SceneError(path, f"has {array.shape[2]} channels, not one", fix)
    if array.shape != tuple(shape):
        raise SceneError(
            path,
            f"is {array.shape[1]}x{array.shape[0]} pixels, the frame {shape[1]}x{shape[0]}",
            fix,
        )
    if array.dtype == bool:
        return array
    values = np.unique(array)
    if not (set(values.tolist()) <= {0, 255} or set(values.tolist()) <= {0, 1}):
        shown = ", ".join(str(v) for v in values[:6]) + (", ..." if values.size > 6 else "")
        raise SceneError(path, f"is not a binary mask (values {shown})", fix)
    return array > 0


def read_mask_files(
    scene_path: Path | str, frame_index: int, n_objects: int, shape: tuple[int, int]
) -> tuple[np.ndarray, list[int]]:
    """Ground-truth labels of one frame from its BOP ``mask_visib/`` files (module doc).

    Args:
        scene_path: scene folder.
        frame_index: frame id.
        n_objects: objects listed for the frame in ``scene_gt.json``.
        shape: (H, W) of the frame.

    Returns:
        labels: (H, W) int32, ``k + 1`` where object ``k``'s mask is set (the first listed
            object where masks overlap), 0 elsewhere;
        visible_px: the label's pixel count of each object.

    Raises:
        SceneError: naming the file, when a mask is missing, extra, unreadable, not binary, not
            of the frame's size, or disagrees with ``px_count_visib`` of ``scene_gt_info.json``.
    """
    scene_path = Path(scene_path)
    paths = mask_file_paths(scene_path, frame_index)
    extra = [position for position in paths if position >= n_objects]
    if extra:
        raise SceneError(
            paths[extra[0]],
            f"is the mask of object position {extra[0]}, but scene_gt.json lists "
            f"{n_objects} objects in frame {frame_index}",
            "remove it, or list the object in scene_gt.json",
        )
    counts = _px_count_visib(scene_path, frame_index, n_objects)
    labels = np.zeros(shape, dtype=np.int32)
    for position in range(n_objects):
        path = scene_path / "mask_visib" / f"{frame_index:06d}_{position:06d}.png"
        if position not in paths:
            raise SceneError(
                path,
                f"is missing: frame {frame_index} has mask files, but none for object position "
                f"{position} of scene_gt.json",
                "add the mask (an empty one when the object is hidden), or remove the frame's "
                "masks to render them from the models",
            )
        mask = _read_mask(path, shape)
        if counts is not None and int(mask.sum()) != counts[position]:
            raise SceneError(
                path,
                f"has {int(mask.sum())} visible pixels, scene_gt_info.json says "
                f"px_count_visib {counts[position]}",
                "regenerate the masks or scene_gt_info.json so they agree",
            )
        labels[mask & (labels == 0)] = position + 1
    visible_px = np.bincount(labels.ravel(), minlength=n_objects + 1)[1:]
    return labels, [int(count) for count in visible_px]


def _px_count_visib(scene_path: Path, frame_index: int, n_objects: int) -> list[int] | None:
    """``px_count_visib`` of each object of the frame, or None when the scene gives none."""
    counts = load_visible_pixel_counts(scene_path)
    if counts is None or frame_index not in counts:
        return None
    if len(counts[frame_index]) != n_objects:
        raise SceneError(
            scene_path / "scene_gt_info.json",
            f"frame {frame_index} lists {len(counts[frame_index])} objects, scene_gt.json "
            f"{n_objects}",
            "regenerate scene_gt_info.json from scene_gt.json",
        )
    return counts[frame_index]


def ground_truth_masks(
    scene_path: Path | str,
    frame_index: int,
    *,
    models_dir: Path | str | None = None,
    renderer: Any = None,
    frame: Frame | None = None,
    walls: bool = True,
    tolerance_m: float = VISIBILITY_TOLERANCE_M,
    mask_files: bool = True,
) -> tuple[np.ndarray, list[int], list[int]]:
    """Visible ground-truth object masks of one frame (BOP visibility rule, module doc): the
    scene's ``mask_visib/`` files of the frame when it has them, else rendered from the models.

    Args:
        scene_path: scene folder with ``scene_gt.json`` (and ``scene_camera.json``, ``depth/``
            unless ``frame`` is given).
        frame_index: frame id.
        models_dir: BOP models folder (default ``<scene>/../models``). Models are loaded once per
            process, and the posed-model renderer is compiled once per scene, then reused.
        renderer: an ``ipr_shapes.rendering.Renderer`` of the frame's size to reuse (else one is made
            and closed).
        frame: the already loaded frame (its ``K``, ``depth_m`` and ``world_from_camera`` are
            used instead of reading the files).
        walls: also render the walls of a generated scene (``synth_walls``) as occluders.
        tolerance_m: visibility tolerance behind the observed depth, metres.
        mask_files: read the frame's BOP ``mask_visib/`` files when there are any (``walls``,
            ``tolerance_m``, ``models_dir`` and ``renderer`` are then not used); False always
            renders.

    Returns:
        labels: (H, W) int32, 0 background, ``k + 1`` for the k-th object of the frame's
            ``scene_gt.json`` list;
        obj_ids: BOP ``obj_id`` of each object, in that order;
        visible_px: visible pixels of each object (the label's pixel count), in that order.
    """
    scene_path = Path(scene_path)
    ground_truth = load_ground_truth(scene_path)
    if frame_index not in ground_truth:
        raise SceneError(
            scene_path / "scene_gt.json",
            f"has no frame {frame_index}",
            f'give the frame-{frame_index} object poses under key "{frame_index}"',
        )
    poses = ground_truth[frame_index]
    if mask_files and mask_file_paths(scene_path, frame_index):
        shape = frame.shape if frame is not None else _frame_shape(scene_path, frame_index)
        labels, visible_px = read_mask_files(scene_path, frame_index, len(poses), shape)
        return labels, [pose.obj_id for pose in poses], visible_px
    if frame is not None:
        K, observed = np.asarray(frame.K, dtype=np.float64), frame.depth_m
        world_from_camera = np.asarray(frame.world_from_camera, dtype=np.float64)
    else:
        K, observed, world_from_camera = _read_frame(scene_path, frame_index)
    height, width = observed.shape
    obj_ids = [pose.obj_id for pose in poses]
    if not poses:
        return np.zeros((height, width), dtype=np.int32), [], []

    boxes = synth_walls(scene_path) if walls else []
    if boxes and world_from_camera is None:
        raise SceneError(
            scene_path / "scene_camera.json",
            "synth.json lists walls but the frame has no camera pose",
            "give cam_R_w2c and cam_t_w2c, or pass walls=False",
        )
    if boxes:
        camera_from_world = invert_transform(world_from_camera)
        boxes = [(half, camera_from_world @ pose) for half, pose in boxes]
    folder = str(Path(models_dir) if models_dir is not None else default_models_dir(scene_path))
    depth, index = _render_posed_models(
        folder,
        obj_ids,
        [pose.camera_from_model for pose in poses],
        boxes,
        K,
        width,
        height,
        renderer,
    )
    consistent = (observed <= 0) | (depth <= observed + np.float32(tolerance_m))
    labels = np.where((index >= 0) & consistent, index + 1, 0).astype(np.int32)
    visible_px = np.bincount(labels.ravel(), minlength=len(poses) + 1)[1:]
    return labels, obj_ids, [int(count) for count in visible_px]


# --------------------------------------------------------------------------------------------
# Overlap scores


@dataclass(frozen=True)
class ObjectSegmentation:
    """Score of one visible ground-truth object against its best predicted segment.

    ``gt_label`` is the object's value in the ground-truth label image; ``matched_label`` the
    best segment's predicted label (None when no segment overlaps the object); pixel counts
    |G|, |S| and |S ∩ G|; precision, recall and F-measure in [0, 1].
    """

    gt_label: int
    gt_px: int
    matched_label: int | None
    segment_px: int
    intersection_px: int
    precision: float
    recall: float
    f_measure: float


@dataclass(frozen=True)
class SegmentationScores:
    """Overlap scores of one predicted label image (definitions in the module doc).

    ``objects`` holds one row per visible ground-truth object (ascending ground-truth label);
    means and ``share_f75`` are over those rows (nan when there is none). ``n_invisible`` counts
    ground-truth objects with fewer than ``min_visible_px`` pixels (left out);
    ``n_segments`` the predicted segments (distinct labels > 0).
    """

    objects: tuple[ObjectSegmentation, ...]
    precision: float
    recall: float
    f_measure: float
    share_f75: float
    n_visible: int
    n_invisible: int
    n_segments: int
    min_visible_px: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict; nan becomes None."""
        return _json_ready(asdict(self))


def _json_ready(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {key: _json_ready(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(item) for item in value]
    return value


def _check_labels(predicted: np.ndarray, ground_truth: np.ndarray) -> None:
    if predicted.shape != ground_truth.shape or predicted.ndim != 2:
        raise ValueError(
            f"label images must be 2-D of the same shape, got {predicted.shape} and "
            f"{ground_truth.shape}"
        )
    for name, array in (("predicted", predicted), ("ground-truth", ground_truth)):
        if not np.issubdtype(array.dtype, np.integer):
            raise ValueError(f"{name} labels must be integers, got {array.dtype}")


@dataclass(frozen=True)
class _BestMatches:
    """Best segment of every ground-truth label (internal; arrays over ``gt_values``)."""

    gt_values: np.ndarray  # (G,) ground-truth labels > 0 present
    gt_px: np.ndarray  # (G,) pixels of each
    matched: np.ndarray  # (G,) best predicted label, 0 when none overlaps
    segment_px: np.ndarray  # (G,) pixels of that segment
    intersection_px: np.ndarray  # (G,)
    n_segments: int


def _compact(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct label values (L,) int64, ascending, with every value <= 0 merged into 0, and
    the index (H*W,) into them of every pixel; a bincount for small label ranges (fast), a sort
    otherwise."""
    flat = np.maximum(labels.ravel().astype(np.int64, copy=False), 0)
    high = int(flat.max()) if flat.size else 0
    if high >= 1 << 20:
        return np.unique(flat, return_inverse=True)
    values = np.flatnonzero(np.bincount(flat, minlength=1))
    lookup = np.zeros(high + 1, dtype=np.int64)
    lookup[values] = np.arange(len(values))
    return values, lookup[flat]


def _best_matches(predicted: np.ndarray, ground_truth: np.ndarray) -> _BestMatches:
    """Contingency table of (ground truth, prediction) labels > 0 via one bincount, then the
    best-F segment of every ground-truth label (ties: larger intersection)."""
    _check_labels(predicted, ground_truth)
    pred_values, pred_index = _compact(predicted)
    gt_values, gt_index = _compact(ground_truth)
    pred_fg, gt_fg = pred_values > 0, gt_values > 0
    n_pred, n_gt = len(pred_values), len(gt_values)
    table = np.bincount(gt_index * n_pred + pred_index, minlength=n_gt * n_pred).reshape(
        n_gt, n_pred
    )
    table = table[gt_fg][:, pred_fg]  # (G, S) intersections of foreground labels
    segment_sizes = np.bincount(pred_index, minlength=n_pred)[pred_fg]  # (S,)
    gt_sizes = np.bincount(gt_index, minlength=n_gt)[gt_fg]  # (G,)
    segments = pred_values[pred_fg]
    count = len(gt_sizes)
    if table.shape[1] == 0:
        zeros = np.zeros(count, dtype=np.int64)
        return _BestMatches(gt_values[gt_fg], gt_sizes, zeros, zeros, zeros, 0)
    f_measure = 2.0 * table / (segment_sizes[None, :] + gt_sizes[:, None])
    best_f = f_measure.max(axis=1, keepdims=True)
    column = np.where(f_measure == best_f, table, -1).argmax(axis=1)
    rows = np.arange(count)
    intersection = table[rows, column]
    overlaps = intersection > 0
    return _BestMatches(
        gt_values=gt_values[gt_fg],
        gt_px=gt_sizes,
        matched=np.where(overlaps, segments[column], 0),
        segment_px=np.where(overlaps, segment_sizes[column], 0),
        intersection_px=intersection,
        n_segments=len(segments),
    )


def _ratios(
    intersection: np.ndarray, segment: np.ndarray, gt: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Precision, recall and F-measure arrays (0 where the intersection is empty)."""
    inter = intersection.astype(np.float64)
    precision = np.divide(inter, segment, out=np.zeros_like(inter), where=segment > 0)
    recall = np.divide(inter, gt, out=np.zeros_like(inter), where=gt > 0)
    total = segment + gt
    f_measure = np.divide(2.0 * inter, total, out=np.zeros_like(inter), where=total > 0)
    return precision, recall, f_measure


def segmentation_scores(
    predicted_labels: np.ndarray,
    gt_labels: np.ndarray,
    *,
    min_visible_px: int = DEFAULT_MIN_VISIBLE_PX,
) -> SegmentationScores:
    """Per-object overlap scores of a predicted label image (OSD/OCID convention, module doc).

    Args:
        predicted_labels: (H, W) int, predicted segment per pixel, labels <= 0 = no segment.
        gt_labels: (H, W) int, ground-truth object per pixel, 0 (or < 0) = background.
        min_visible_px: ground-truth objects with fewer pixels are left out.
    """
    predicted = np.asarray(predicted_labels)
    ground_truth = np.asarray(gt_labels)
    best = _best_matches(predicted, ground_truth)
    precision, recall, f_measure = _ratios(best.intersection_px, best.segment_px, best.gt_px)
    visible = best.gt_px >= min_visible_px
    rows = tuple(
        ObjectSegmentation(
            gt_label=int(best.gt_values[i]),
            gt_px=int(best.gt_px[i]),
            matched_label=int(best.matched[i]) if best.intersection_px[i] > 0 else None,
            segment_px=int(best.segment_px[i]),
            intersection_px=int(best.intersection_px[i]),
            precision=float(precision[i]),
            recall=float(recall[i]),
            f_measure=float(f_measure[i]),
        )
        for i in np.flatnonzero(visible)
    )
    n_visible = int(visible.sum())

    def mean(values: np.ndarray) -> float:
        return float(values[visible].mean()) if n_visible else math.nan

    return SegmentationScores(
        objects=rows,
        precision=mean(precision),
        recall=mean(recall),
        f_measure=mean(f_measure),
        share_f75=mean((f_measure >= F_THRESHOLD).astype(np.float64)),
        n_visible=n_visible,
        n_invisible=int((~visible).sum()),
        n_segments=best.n_segments,
        min_visible_px=int(min_visible_px),
    )


# --------------------------------------------------------------------------------------------
# Id consistency


@dataclass(frozen=True)
class LostId:
    """A counted (object, later frame) pair that did not keep its frame-0 predicted id.

    Attributes:
        frame: index of the later frame.
        obj_id, occurrence: the ground-truth object (its BOP ``obj_id`` and which occurrence of
            that ``obj_id`` in the frame's list, from 0).
        frame0_label: the predicted label of the object's best segment in frame 0.
        label: the predicted label of its best segment in ``frame``, None when no segment
            reaches ``ID_MATCH_MIN_F`` there.
        kind: ``"no segment"`` (label None: a segmentation failure no tracker can mend),
            ``"other id"`` (the label is another counted object's frame-0 label) or ``"new id"``.
        frame0_label_shown: whether ``frame0_label`` is in ``frame``'s prediction at all.
        frame0_label_holder: (obj_id, occurrence) of a visible object whose best segment in
            ``frame`` (F >= ``ID_MATCH_MIN_F``) carries ``frame0_label`` (another object took
            the id), else None.
        piece_flip: ``label`` was, in frame 0, another piece of this object (more than half of
            its frame-0 pixels on the object): the object stays split, each piece keeps its
            id, and which piece is the best segment changed (its pieces' sizes swapped). A
            tracker that keeps each piece's id loses such a pair; joining the pieces ends it.
    """

    frame: int
    obj_id: int
    occurrence: int
    frame0_label: int
    label: int | None
    kind: str
    frame0_label_shown: bool
    frame0_label_holder: tuple[int, int] | None
    piece_flip: bool = False


@dataclass(frozen=True)
class IdConsistency:
    """Id consistency over a sequence (definition in the module doc): ``consistent`` of
    ``counted`` (object, later frame) pairs kept their predicted id; ``share`` =
    consistent / counted (nan when nothing is counted); ``lost`` the other counted pairs, in
    frame order, for the diagnosis of tracking failures."""

    consistent: int
    counted: int
    share: float
    lost: tuple[LostId, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict; nan becomes None."""
        return _json_ready(asdict(self))


def _object_keys(obj_ids: Sequence[int]) -> list[tuple[int, int]]:
    """(obj_id, occurrence) of each object of a frame, so that duplicates pair in order."""
    seen: Counter[int] = Counter()
    keys = []
    for obj_id in obj_ids:
        keys.append((int(obj_id), seen[int(obj_id)]))
        seen[int(obj_id)] += 1
    return keys


def _frame_ids(
    predicted: np.ndarray,
    ground_truth: np.ndarray,
    obj_ids: Sequence[int],
    min_visible_px: int,
    min_f: float,
) -> dict[tuple[int, int], int | None]:
    """Visible objects of a frame -> predicted label of their best segment when F >= min_f,
    else None."""
    best = _best_matches(np.asarray(predicted), np.asarray(ground_truth))
    _, _, f_measure = _ratios(best.intersection_px, best.segment_px, best.gt_px)
    keys = _object_keys(obj_ids)
    result: dict[tuple[int, int], int | None] = {}
    for value, pixels, label, score in zip(
        best.gt_values, best.gt_px, best.matched, f_measure, strict=True
    ):
        if pixels < min_visible_px:
            continue
        if not 1 <= value <= len(keys):
            raise ValueError(
                f"ground-truth label {int(value)} has no obj_id ({len(keys)} objects given)"
            )
        result[keys[int(value) - 1]] = int(label) if score >= min_f and label > 0 else None
    return result


def id_consistency_counts(
    predicted_labels_per_frame: Sequence[np.ndarray],
    gt_labels_per_frame: Sequence[np.ndarray],
    gt_obj_ids_per_frame: Sequence[Sequence[int]],
    *,
    min_visible_px: int = DEFAULT_MIN_VISIBLE_PX,
    min_f: float = ID_MATCH_MIN_F,
) -> IdConsistency:
    """Counted and consistent (object, later frame) pairs of a sequence (module doc).

    Args:
        predicted_labels_per_frame: (H, W) int tracked labels per frame (<= 0 = none).
        gt_labels_per_frame: (H, W) int ground-truth labels per frame, ``k + 1`` for the k-th
            object of that frame's ``gt_obj_ids_per_frame`` list, 0 background.
        gt_obj_ids_per_frame: BOP ``obj_id`` of each ground-truth label, per frame.
        min_visible_px: visibility threshold (ground-truth pixels) in each frame.
        min_f: F-measure a best segment needs to give the object a predicted id.
    """
    counts = {
        len(predicted_labels_per_frame),
        len(gt_labels_per_frame),
        len(gt_obj_ids_per_frame),
    }
    if len(counts) != 1:
        raise ValueError("give the same number of frames of predictions, labels and obj_ids")
    ids = [
        _frame_ids(predicted, truth, obj_ids, min_visible_px, min_f)
        for predicted, truth, obj_ids in zip(
            predicted_labels_per_frame, gt_labels_per_frame, gt_obj_ids_per_frame, strict=True
        )
    ]
    if not ids:
        return IdConsistency(0, 0, math.nan)
    first = {key: label for key, label in ids[0].items() if label is not None}
    frame0_labels = set(first.values())
    frame0_predicted = np.asarray(predicted_labels_per_frame[0])
    frame0_truth = np.asarray(gt_labels_per_frame[0])
    frame0_values = {
        key: value for value, key in enumerate(_object_keys(gt_obj_ids_per_frame[0]), 1)
    }
    consistent = counted = 0
    lost = []
    for frame, (later, predicted) in enumerate(
        zip(ids[1:], predicted_labels_per_frame[1:], strict=True), start=1
    ):
        holders = {label: key for key, label in later.items() if label is not None}
        for key, label in first.items():
            if key not in later:
                continue
            counted += 1
            if later[key] == label:
                consistent += 1
                continue
            kind = (
                "no segment"
                if later[key] is None
                else "other id"
                if later[key] in frame0_labels
                else "new id"
            )
            shown = bool(np.any(np.asarray(predicted) == label))
            flip = False
            if later[key] is not None:
                piece = frame0_predicted == later[key]
                on_object = np.count_nonzero(piece & (frame0_truth == frame0_values[key]))
                flip = bool(2 * on_object > np.count_nonzero(piece))
            lost.append(
                LostId(frame, *key, label, later[key], kind, shown, holders.get(label), flip)
            )
    share = consistent / counted if counted else math.nan
    return IdConsistency(consistent, counted, share, tuple(lost))


def id_consistency(
    predicted_labels_per_frame: Sequence[np.ndarray],
    gt_labels_per_frame: Sequence[np.ndarray],
    gt_obj_ids_per_frame: Sequence[Sequence[int]],
) -> float:
    """Share in [0, 1] of (object, later frame) pairs whose object keeps its frame-0 predicted
    id (nan when no pair is counted); see ``id_consistency_counts`` and the module doc."""
    return id_consistency_counts(
        predicted_labels_per_frame, gt_labels_per_frame, gt_obj_ids_per_frame
    ).share
