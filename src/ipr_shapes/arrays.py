"""A scene from arrays in memory (``ipr_shapes.from_arrays``): the same ``Scene`` that ``load_scene``
reads from a folder, validated by the same rules, for data that never was a BOP folder.

Why: a robot program holds its frames as numpy arrays; writing a BOP folder only to read it back
costs time and rounds depth to the file's units. Units, frames and checks are the scene
contract's (docs/FORMATS.md): metres, OpenCV camera frames, a z-up world; each failure raises
``ipr_shapes.errors.ArrayInputError`` (a ``ValueError``) naming the argument, the problem and the fix.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes.camera import make_transform
from ipr_shapes.errors import ArrayInputError, SceneError
from ipr_shapes.scene import (
    GRAVITY_FIX,
    PLAUSIBLE_DEPTH_M,
    Frame,
    Push,
    Pusher,
    Scene,
    _number_array,
    _positive_number,
    _rotation,
    _unit_vector,
    world_from_support_plane,
)

#: ``Scene.path`` of a scene made from arrays when no name is given.
DEFAULT_NAME = "<arrays>"


@contextlib.contextmanager
def _as_array_error() -> Iterator[None]:
    """Re-raise the scene helpers' SceneError (whose path is the argument's name) as
    ArrayInputError, so every failure here is a ValueError with the same words."""
    try:
        yield
    except ArrayInputError:
        raise
    except SceneError as error:
        fix = error.fix
        if fix == GRAVITY_FIX:
            fix = (
                "give the camera poses (world_from_camera=...) or the up direction in camera "
                "coordinates (up_camera=(0, -1, 0) for a camera held level)"
            )
        raise ArrayInputError(str(error.path), error.problem, fix) from None


def _stack(value: Any, name: str, single_ndim: int) -> list[np.ndarray]:
    """One array per frame: a sequence of arrays, an array with a leading frame axis, or one
    frame's array (``single_ndim`` dimensions)."""
    if isinstance(value, np.ndarray):
        if value.ndim == single_ndim:
            return [value]
        if value.ndim == single_ndim + 1:
            return list(value)
        raise ArrayInputError(
            name,
            f"has {value.ndim} dimensions {value.shape}",
            f"give one frame with {single_ndim} dimensions or a stack with {single_ndim + 1}",
        )
    if isinstance(value, list | tuple):
        if not value:
            raise ArrayInputError(name, "no frames", "give at least one frame")
        return [np.asarray(item) for item in value]
    raise ArrayInputError(
        name, f"must be a numpy array or a list of arrays, got {type(value).__name__}"
    )


def _check_rgb(rgb: np.ndarray, where: str) -> np.ndarray:
    if rgb.dtype != np.uint8:
        raise ArrayInputError(
            where,
            f"dtype is {rgb.dtype}, not uint8",
            "give 8-bit RGB, e.g. (rgb * 255).round().astype(np.uint8) for values in 0-1",
        )
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ArrayInputError(
            where, f"shape is {rgb.shape}, not (H, W, 3)", "give RGB images (drop alpha: [..., :3])"
        )
    return np.ascontiguousarray(rgb)


def _depth_metres(depth: np.ndarray, depth_scale: float | None, where: str) -> np.ndarray:
    """(H, W) float32 metres, 0 where no reading; float input is metres (NaN or inf: no
    reading), uint16 input is ``value x depth_scale`` millimetres (as in the BOP files)."""
    if depth.ndim != 2:
        raise ArrayInputError(where, f"shape is {depth.shape}, not (H, W)", "give one depth map")
    if depth.dtype == np.uint16:
        if depth_scale is None:
            raise ArrayInputError(
                where,
                "uint16 depth needs depth_scale (mm per depth unit)",
                "pass depth_scale=1.0 for millimetres (or give float depth in metres)",
            )
        with _as_array_error():
            scale = _positive_number(depth_scale, Path("depth_scale"), "depth_scale")
        # The same arithmetic as load_scene, so that a folder and its arrays give equal depth.
        return depth.astype(np.float32) * np.float32(scale / 1000.0)
    if np.issubdtype(depth.dtype, np.floating):
        if depth_scale is not None:
            raise ArrayInputError(
                where,
                "depth_scale was given but the depth is float (metres)",
                "leave depth_scale out for float depth, or give uint16 depth units",
            )
        metres = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
        if (metres < 0).any():
            raise ArrayInputError(
                where, "depth has negative values", "give depth along the optical axis, >= 0"
            )
        return metres
    raise ArrayInputError(
        where,
        f"depth dtype is {depth.dtype}",
        "give float depth in metres, or uint16 units with depth_scale (mm per unit)",
    )


def _check_depth_range(depth_m: np.ndarray, where: str, scale_hint: str) -> None:
    valid = depth_m[depth_m > 0]
    if valid.size == 0:
        raise ArrayInputError(
            where, "depth has no valid reading (all zero)", "0 (or NaN) means no reading"
        )
    median = float(np.median(valid))
    if not PLAUSIBLE_DEPTH_M[0] <= median <= PLAUSIBLE_DEPTH_M[1]:
        raise ArrayInputError(
            where,
            f"median depth is {median:.3g} m (expected {PLAUSIBLE_DEPTH_M[0]}-"
            f"{PLAUSIBLE_DEPTH_M[1]} m): likely a unit error",
            scale_hint,
        )


def _intrinsics(K: Any, count: int) -> list[np.ndarray]:
    try:
        shape = np.shape(K)
    except ValueError:  # a ragged list
        shape = None
    if shape == (3, 3):
        items, names = [K], ["K"]
    elif shape == (count, 3, 3):
        items, names = list(K), [f"K[{index}]" for index in range(count)]
    else:
        raise ArrayInputError(
            "K",
            f"shape is {shape}",
            f"give one (3, 3) matrix or one per frame ({count}, 3, 3)",
        )
    result = []
    for item, where in zip(items, names, strict=True):
        with _as_array_error():
            K_frame = _number_array(item, 9, Path(where), "cam_K").reshape(3, 3)
        if K_frame[0, 0] <= 0 or K_frame[1, 1] <= 0:
            raise ArrayInputError(where, "focal lengths must be positive", "give fx, fy > 0 (px)")
        if not np.allclose(K_frame[2], [0, 0, 1]) or K_frame[1, 0] != 0:
            raise ArrayInputError(
                where,
                "not a pinhole intrinsic matrix",
                "use [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]",
            )
        result.append(K_frame)
    return result * count if len(result) == 1 and count > 1 else result


def _shape(value: Any) -> tuple[int, ...] | None:
    """``np.shape`` of a value, None for a ragged sequence (such as (R, t) pairs)."""
    try:
        return np.shape(value)
    except ValueError:
        return None


def _is_rotation_translation(value: Any) -> bool:
    return isinstance(value, tuple) and len(value) == 2 and _shape(value[0]) == (3, 3)


def _pose(value: Any, where: str) -> np.ndarray:
    """A world-from-camera (4, 4) from a (4, 4) matrix or an (R (3, 3), t (3,) m) pair."""
    if _is_rotation_translation(value):
        rotation, translation = value
    else:
        with _as_array_error():
            matrix = _number_array(value, 16, Path(where), "world_from_camera").reshape(4, 4)
        if not np.allclose(matrix[3], [0, 0, 0, 1]):
            raise ArrayInputError(
                where, "bottom row is not [0, 0, 0, 1]", "give a rigid 4x4 transform"
            )
        rotation, translation = matrix[:3, :3], matrix[:3, 3]
    with _as_array_error():
        rotation = _rotation(rotation, Path(where), "rotation")
        translation = _number_array(translation, 3, Path(where), "translation (m)")
    return make_transform(rotation, translation)


def _poses(world_from_camera: Any, count: int) -> list[np.ndarray] | None:
    """Per frame world-from-camera (4, 4), or None when no pose is given."""
    if world_from_camera is None:
        return None
    if _is_rotation_translation(world_from_camera) or _shape(world_from_camera) == (4, 4):
        return [_pose(world_from_camera, "world_from_camera")] * count  # a static camera
    if isinstance(world_from_camera, np.ndarray | list | tuple) and len(world_from_camera) == count:
        return [
            _pose(item, f"world_from_camera[{index}]")
            for index, item in enumerate(world_from_camera)
        ]
    raise ArrayInputError(
        "world_from_camera",
        f"shape is {_shape(world_from_camera)} for {count} frames",
        f"give one (4, 4) transform, ({count}, 4, 4), or (R, t) pairs, one per frame",
    )


def _actions_transform(actions_frame: str, frames: Sequence[Frame], has_poses: bool) -> np.ndarray:
    """World from the pushes' coordinates (``"world"`` or ``"camera:<i>"``, as actions.json)."""
    if actions_frame == "world":
        if not has_poses:
            raise ArrayInputError(
                "pushes",
                "pushes are in the world frame but no camera pose was given",
                'give world_from_camera, or pushes in camera coordinates with actions_frame="camera:0"',
            )
        return np.eye(4)
    match = re.fullmatch(r"camera:(\d+)", str(actions_frame))
    if not match or int(match.group(1)) >= len(frames):
        raise ArrayInputError(
            "actions_frame",
            f"unknown frame {actions_frame!r}",
            'use "world" or "camera:<i>" with an existing frame',
        )
    return frames[int(match.group(1))].world_from_camera


def _pusher(pusher: Pusher | None, rotation: np.ndarray) -> Pusher:
    pusher = pusher if pusher is not None else Pusher()
    if not isinstance(pusher, Pusher):
        raise ArrayInputError(
            "pusher", f"is a {type(pusher).__name__}", "give an ipr_shapes.scene.Pusher"
        )
    where = Path("pusher")
    with _as_array_error():
        radius = _positive_number(pusher.radius_m, where, "radius_m")
        length = _positive_number(pusher.length_m, where, "length_m")
        axis = _unit_vector(pusher.axis, where, "axis")
    if length < 2 * radius:
        raise ArrayInputError("pusher", "length_m is shorter than its two caps (2 x radius_m)")
    return Pusher(radius, length, rotation @ axis)


def _pushes(pushes: Sequence[Push], count: int, transform: np.ndarray) -> tuple[Push, ...]:
    rotation, translation = transform[:3, :3], transform[:3, 3]
    result = []
    for number, push in enumerate(pushes):
        where = f"pushes[{number}]"
        if not isinstance(push, Push):
            raise ArrayInputError(
                where, f"is a {type(push).__name__}", "give ipr_shapes.scene.Push"
            )
        for key in ("before_frame", "after_frame"):
            value = getattr(push, key)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ArrayInputError(where, f"{key} {value!r} is not a frame index")
            if not 0 <= value < count:
                raise ArrayInputError(
                    where,
                    f"{key} {value} names a frame that does not exist",
                    f"use frame indices 0..{count - 1}",
                )
        if push.after_frame <= push.before_frame:
            raise ArrayInputError(where, "after_frame must come after before_frame")
        with _as_array_error():
            start = _number_array(push.start_m, 3, Path(where), "start_m")
            direction = _unit_vector(push.direction, Path(where), "direction")
            distance = _positive_number(push.distance_m, Path(where), "distance_m")
            speed = _positive_number(push.speed_m_s, Path(where), "speed_m_s")
        result.append(
            Push(
                int(push.before_frame),
                int(push.after_frame),
                rotation @ start + translation,
                rotation @ direction,
                distance,
                speed,
            )
        )
    result.sort(key=lambda push: push.before_frame)
    return tuple(result)


def from_arrays(
    rgb: np.ndarray | Sequence[np.ndarray],
    depth: np.ndarray | Sequence[np.ndarray],
    K: np.ndarray | Sequence[np.ndarray],
    *,
    depth_scale: float | None = None,
    world_from_camera: Any = None,
    pushes: Sequence[Push] = (),
    pusher: Pusher | None = None,
    actions_frame: str = "world",
    robot_masks: Sequence[np.ndarray | None] | None = None,
    up_camera: Sequence[float] | None = None,
    plane_seed: int = 0,
    name: str | Path = DEFAULT_NAME,
) -> Scene:
    """A validated ``Scene`` from frames in memory, equal to what ``load_scene`` reads from the
    same data written as a folder.

    Args:
        rgb: per frame (H, W, 3) uint8 RGB: an (N, H, W, 3) array, a list, or one frame.
        depth: per frame (H, W) depth along the optical axis: float metres (0, NaN or inf: no
            reading), or uint16 units of ``depth_scale`` millimetres (BOP's convention).
        K: (3, 3) pinhole intrinsics in pixels, shared, or one per frame (N, 3, 3).
        depth_scale: mm per unit of uint16 depth (1.0 for millimetres); only for uint16.
        world_from_camera: camera poses (OpenCV camera frame to a z-up world, metres): one (4, 4)
            (a static camera), (N, 4, 4), or (R (3, 3), t (3,)) pairs with x_w = R x_c + t.
            None: the camera is static and the world frame comes from frame 0's support, as
            for a folder without poses (``up_camera`` helps when the data cannot tell gravity).
        pushes: ``ipr_shapes.scene.Push`` in ``actions_frame`` coordinates, frames by index (0..N-1).
        pusher: the capsule end effector (axis in ``actions_frame``); default ``Pusher()`` when
            there are pushes, None without.
        actions_frame: ``"world"`` (needs poses) or ``"camera:<i>"`` (frame i's camera frame).
        robot_masks: per frame (H, W) bool (True on robot pixels) or None.
        up_camera: the up direction in camera coordinates (scenes without poses only).
        plane_seed: seed of the support plane fit (scenes without poses).
        name: ``Scene.path``; logs and provenance name the scene by it.

    Raises:
        ArrayInputError (a ValueError): what is wrong with which argument, and the fix.
    """
    rgbs = _stack(rgb, "rgb", 3)
    depths = _stack(depth, "depth", 2)
    count = len(rgbs)
    if len(depths) != count:
        raise ArrayInputError(
            "depth", f"{len(depths)} depth maps for {count} rgb images", "give one per frame"
        )
    intrinsics = _intrinsics(K, count)
    poses = _poses(world_from_camera, count)
    if poses is not None and up_camera is not None:
        raise ArrayInputError(
            "up_camera",
            "an up direction was given but camera poses fix gravity",
            "leave out up_camera when giving world_from_camera",
        )
    if robot_masks is not None and len(robot_masks) != count:
        raise ArrayInputError(
            "robot_masks", f"{len(robot_masks)} masks for {count} frames", "give one per frame"
        )
    hint = (
        "give float depth in metres (divide millimetres by 1000)"
        if depth_scale is None
        else "set depth_scale to the millimetres per depth unit (1.0 for mm, 0.1 for 0.1 mm)"
    )
    images = []
    for index in range(count):
        colour = _check_rgb(rgbs[index], f"rgb[{index}]")
        depth_m = _depth_metres(depths[index], depth_scale, f"depth[{index}]")
        if colour.shape[:2] != depth_m.shape:
            raise ArrayInputError(
                f"depth[{index}]",
                f"depth is {depth_m.shape[1]}x{depth_m.shape[0]} but rgb is "
                f"{colour.shape[1]}x{colour.shape[0]}",
                "rgb and depth of a frame must have the same size (register depth to colour)",
            )
        _check_depth_range(depth_m, f"depth[{index}]", hint)
        mask = None
        if robot_masks is not None and robot_masks[index] is not None:
            mask = np.asarray(robot_masks[index])
            if mask.shape != depth_m.shape:
                raise ArrayInputError(
                    f"robot_masks[{index}]",
                    f"mask is {mask.shape}, image is {depth_m.shape}",
                    "masks must have the size of the frame's images",
                )
            mask = mask > 0
        images.append((colour, depth_m, mask))

    note, source = "", "camera_poses"
    if poses is None:
        source = "support_plane"
        with _as_array_error():
            shared, note = world_from_support_plane(
                images[0][1],
                intrinsics[0],
                seed=plane_seed,
                path="depth[0]",
                up_camera=up_camera,
                with_note=True,
            )
        poses = [shared] * count
    frames = tuple(
        Frame(index, colour, depth_m, intrinsics[index], poses[index], mask)
        for index, (colour, depth_m, mask) in enumerate(images)
    )
    scene_pusher, scene_pushes = None, ()
    if pushes or pusher is not None:
        transform = _actions_transform(actions_frame, frames, source == "camera_poses")
        scene_pusher = _pusher(pusher, transform[:3, :3])
        scene_pushes = _pushes(list(pushes), count, transform)
    return Scene(Path(name), frames, scene_pushes, scene_pusher, source, note)
