"""Scene directories (``SCENE_FORMAT.md``, contract version 1): read, validate, write.

A scene is a BOP scene folder (``scene_camera.json``, ``rgb/``, ``depth/``) plus optional robot
pushes (``actions.json``) and robot masks (``mask_robot/``). Everything in memory is in metres, in
the world frame (z up, gravity -z) or the frame's OpenCV camera frame; millimetres exist only in
the files. Ground truth (``scene_gt.json``, models) is read by separate functions that only
evaluation and benchmarks call: inference never reads it.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from ipr.atomic import staged_directory
from ipr.camera import backproject, invert_transform, make_transform
from ipr.errors import SceneError
from ipr.geometry.planes import Plane, fit_plane_ransac
from ipr.geometry.support import SupportChoiceConfig, choose_support

log = logging.getLogger(__name__)

ACTIONS_FORMAT = "ipr-actions/1"
FRAME_NAME = re.compile(r"^(\d{6})\.(png|jpg|jpeg)$")
#: Plausible range of the median valid depth of a frame (m); outside it the depth scale is
#: almost certainly in the wrong unit.
PLAUSIBLE_DEPTH_M = (0.1, 5.0)
#: Tolerance on |direction| = 1 and on rotation orthonormality.
UNIT_TOLERANCE = 1e-3
#: With a given up direction, the support's normal is within this angle of it (deg): a rough
#: up (a camera taken as level that looks down at the table) still finds the table, and walls
#: (90 degrees) are out.
UP_MAX_TILT_DEG = 45.0
#: How to fix a scene whose gravity cannot be found from its data (error messages).
GRAVITY_FIX = (
    "give the camera pose (cam_R_w2c, cam_t_w2c) in scene_camera.json, or the up direction "
    "in camera coordinates with --up X Y Z (load_scene(path, up_camera=...); 0 -1 0 for a "
    "camera held level)"
)


@dataclass(frozen=True, eq=False)
class Frame:
    """One RGB-D capture.

    Attributes:
        index: frame id (0, 1, ...), in capture order.
        rgb: (H, W, 3) uint8.
        depth_m: (H, W) float32 depth along the optical axis in metres; 0 where no reading.
        K: (3, 3) float64 intrinsics in pixels.
        world_from_camera: (4, 4) float64, OpenCV camera frame to world frame, metres.
        robot_mask: (H, W) bool, True on pixels of the robot or pusher, or None.
    """

    index: int
    rgb: np.ndarray
    depth_m: np.ndarray
    K: np.ndarray
    world_from_camera: np.ndarray
    robot_mask: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """Image (height, width) in pixels."""
        return self.depth_m.shape

    def points_world(self) -> np.ndarray:
        """(H, W, 3) world-frame points of every pixel (meaningless where depth is 0)."""
        # Imported here: numba's slow import is only worth paying where points are needed.
        from ipr.geometry.kernels import world_points

        return world_points(self.depth_m, self.K, self.world_from_camera)


@dataclass(frozen=True, eq=False)
class Pusher:
    """The capsule end effector: radius and tip-to-tip length (m), unit axis (3,) in world."""

    radius_m: float = 0.01
    length_m: float = 0.15
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))


@dataclass(frozen=True, eq=False)
class Push:
    """A straight push of the pusher's centre, in the world frame.

    The pusher moves from ``start_m`` (3,) along unit ``direction`` (3,) for ``distance_m`` at
    ``speed_m_s``, after frame ``before_frame`` and before ``after_frame`` was captured.
    """

    before_frame: int
    after_frame: int
    start_m: np.ndarray
    direction: np.ndarray
    distance_m: float
    speed_m_s: float

    @property
    def end_m(self) -> np.ndarray:
        """Where the pusher's centre stops (3,), world frame, metres."""
        return self.start_m + self.direction * self.distance_m


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene: frames in capture order and the robot's pushes, in the world frame.

    ``world_frame_source`` is ``"camera_poses"`` when the files give camera poses, or
    ``"support_plane"`` when the world frame was built from the support found in frame 0;
    ``support_note`` then says which plane that was and why (``ipr.geometry.support``).
    """

    path: Path
    frames: tuple[Frame, ...]
    pushes: tuple[Push, ...] = ()
    pusher: Pusher | None = None
    world_frame_source: str = "camera_poses"
    support_note: str = ""

    @property
    def is_dynamic(self) -> bool:
        """True when the robot acted between frames."""
        return bool(self.pushes)


@dataclass(frozen=True, eq=False)
class ObjectPose:
    """Ground truth of one object in one frame: BOP ``obj_id`` and its camera-from-model (4, 4) in
    metres."""

    obj_id: int
    camera_from_model: np.ndarray


# --------------------------------------------------------------------------------------------
# Reading helpers


def read_json(path: Path, what: str) -> Any:
    """Parse a JSON file, rejecting NaN/Infinity literals; SceneError on any problem."""
    if not path.is_file():
        raise SceneError(path, f"{what} is missing", f"create {path.name} as the contract says")

    def reject_constant(name: str) -> Any:
        raise SceneError(path, f"{what} contains {name}", "write finite numbers only")

    try:
        return json.loads(path.read_text(encoding="utf-8"), parse_constant=reject_constant)
    except json.JSONDecodeError as error:
        raise SceneError(
            path,
            f"{what} is not valid JSON: {error.msg} at line {error.lineno} column {error.colno}",
            "correct the JSON syntax",
        ) from None
    except UnicodeDecodeError:
        raise SceneError(path, f"{what} is not UTF-8 text", "save it as UTF-8 JSON") from None


def _number_array(value: Any, count: int, path: Path, key: str) -> np.ndarray:
    """A finite float64 array of ``count`` numbers (nested lists are flattened)."""
    try:
        array = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise SceneError(
            path, f"'{key}' must be a list of {count} numbers, got {value!r}"
        ) from None
    if array.size != count:
        raise SceneError(path, f"'{key}' must hold {count} numbers, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise SceneError(path, f"'{key}' contains NaN or inf", "write finite numbers only")
    return array


def _positive_number(value: Any, path: Path, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SceneError(path, f"'{key}' must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise SceneError(path, f"'{key}' must be positive and finite, got {value}")
    return float(value)


def _unit_vector(value: Any, path: Path, key: str) -> np.ndarray:
    vector = _number_array(value, 3, path, key)
    norm = float(np.linalg.norm(vector))
    if norm < 1e-9:
        raise SceneError(path, f"'{key}' is the zero vector", "give a unit direction")
    if abs(norm - 1.0) > UNIT_TOLERANCE:
        raise SceneError(
            path, f"'{key}' is not a unit vector (length {norm:.4f})", "normalise it to length 1"
        )
    return vector / norm


def _frame_files(folder: Path, allowed: tuple[str, ...]) -> dict[int, Path]:
    """Frame id -> file in ``folder`` (``NNNNNN.ext``); other files are ignored."""
    files: dict[int, Path] = {}
    if not folder.is_dir():
        return files
    for entry in folder.iterdir():
        match = FRAME_NAME.match(entry.name)
        if match and match.group(2) in allowed:
            index = int(match.group(1))
            if index in files:
                raise SceneError(
                    entry,
                    f"frame {index} has two files in {folder.name}/",
                    "keep one file per frame",
                )
            files[index] = entry
    return files


def _check_consecutive(ids: Iterable[int], path: Path, what: str) -> list[int]:
    ordered = sorted(ids)
    if not ordered:
        raise SceneError(path, f"{what}: no frames", "add frame 0")
    expected = list(range(len(ordered)))
    if ordered != expected:
        missing = sorted(set(range(ordered[-1] + 1)) - set(ordered))
        raise SceneError(
            path,
            f"{what}: frame ids must be consecutive from 0; missing {missing[:10]}",
            "renumber the frames 0, 1, 2, ... in capture order",
        )
    return ordered


def _read_rgb(path: Path) -> np.ndarray:
    try:
        with Image.open(path) as image:
            image.load()
            if image.mode not in ("RGB", "RGBA", "L", "P"):
                raise SceneError(path, f"RGB image has mode {image.mode}", "save 8-bit RGB")
            return np.asarray(image.convert("RGB"), dtype=np.uint8)
    except (OSError, SyntaxError) as error:
        raise SceneError(path, f"cannot read image: {error}", "write a valid PNG/JPEG") from None


def _read_depth_units(path: Path) -> np.ndarray:
    try:
        with Image.open(path) as image:
            image.load()
            array = np.asarray(image)
    except (OSError, SyntaxError) as error:
        raise SceneError(path, f"cannot read depth image: {error}", "write a 16-bit PNG") from None
    if array.ndim != 2 or array.dtype not in (np.uint16, np.int32) or image.mode == "L":
        raise SceneError(
            path,
            f"depth must be a single-channel 16-bit PNG, got mode {image.mode} dtype {array.dtype}",
            "save depth as uint16 PNG with depth in mm = value x depth_scale",
        )
    if array.dtype == np.int32:  # PIL opens some 16-bit PNGs as 32-bit integers
        if array.min() < 0 or array.max() > 65535:
            raise SceneError(path, "depth values outside the 16-bit range", "save as uint16 PNG")
        array = array.astype(np.uint16)
    return array


def _read_mask(path: Path) -> np.ndarray:
    try:
        with Image.open(path) as image:
            return np.asarray(image.convert("L")) > 0
    except (OSError, SyntaxError) as error:
        raise SceneError(path, f"cannot read mask: {error}", "write a PNG mask") from None


def _rotation(value: Any, path: Path, key: str) -> np.ndarray:
    rotation = _number_array(value, 9, path, key).reshape(3, 3)
    if (
        np.abs(rotation @ rotation.T - np.eye(3)).max() > UNIT_TOLERANCE
        or np.linalg.det(rotation) < 0
    ):
        raise SceneError(path, f"'{key}' is not a rotation matrix", "give an orthonormal R, det +1")
    return rotation


# --------------------------------------------------------------------------------------------
# Loading


def load_scene(
    path: Path | str, *, plane_seed: int = 0, up_camera: Sequence[float] | None = None
) -> Scene:
    """Read and validate a scene directory; raise SceneError naming the file and the fix.

    The world frame comes from the camera poses when every frame has one; otherwise the camera is
    taken as static and the world frame is built from the support found in frame 0
    (``world_from_support_plane``: z = the support's normal towards the camera, origin = the
    camera centre projected on it, x = the camera's x axis projected on it). ``up_camera``
    (3 numbers, any length) is the up direction in camera coordinates, for scenes without camera
    poses whose gravity the data cannot tell: the support is then the plane the objects rest on
    among the planes within 45 degrees of perpendicular to it (``UP_MAX_TILT_DEG``).
    """
    root = Path(path)
    if not root.is_dir():
        raise SceneError(
            root, "scene directory not found", "pass the folder holding scene_camera.json"
        )
    camera_path = root / "scene_camera.json"
    cameras = read_json(camera_path, "scene_camera.json")
    if not isinstance(cameras, dict) or not cameras:
        raise SceneError(camera_path, 'must map frame ids "0", "1", ... to camera entries')
    try:
        camera_ids = {int(key): value for key, value in cameras.items()}
    except ValueError:
        raise SceneError(camera_path, 'keys must be frame ids such as "0"') from None
    ids = _check_consecutive(camera_ids, camera_path, "scene_camera.json")

    rgb_files = _frame_files(root / "rgb", ("png", "jpg", "jpeg"))
    depth_files = _frame_files(root / "depth", ("png",))
    for folder, files in (("rgb", rgb_files), ("depth", depth_files)):
        if not (root / folder).is_dir():
            raise SceneError(
                root / folder, f"{folder}/ folder is missing", "add one image per frame"
            )
        _check_consecutive(files, root / folder, f"{folder}/")
        if sorted(files) != ids:
            raise SceneError(
                root / folder,
                f"{folder}/ has frames {sorted(files)[:10]} but scene_camera.json has {ids[:10]}",
                "give one image per frame listed in scene_camera.json",
            )
    mask_files = _frame_files(root / "mask_robot", ("png",))

    intrinsics, scales, poses = {}, {}, {}
    for index in ids:
        entry = camera_ids[index]
        where = f"frame {index}"
        if not isinstance(entry, dict):
            raise SceneError(
                camera_path, f"{where}: entry must be an object with cam_K, depth_scale"
            )
        if "cam_K" not in entry:
            raise SceneError(camera_path, f"{where}: 'cam_K' is missing", "add the 3x3 intrinsics")
        K = _number_array(entry["cam_K"], 9, camera_path, f"{where} cam_K").reshape(3, 3)
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise SceneError(
                camera_path,
                f"{where}: cam_K focal lengths must be positive",
                "give fx, fy > 0 in pixels",
            )
        if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
            raise SceneError(
                camera_path,
                f"{where}: cam_K is not a pinhole intrinsic matrix",
                "use [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]",
            )
        intrinsics[index] = K
        if "depth_scale" not in entry:
            raise SceneError(
                camera_path,
                f"{where}: 'depth_scale' is missing",
                "add mm per depth unit (1.0 for millimetre PNGs)",
            )
        scales[index] = _positive_number(entry["depth_scale"], camera_path, f"{where} depth_scale")
        has_r, has_t = "cam_R_w2c" in entry, "cam_t_w2c" in entry
        if has_r != has_t:
            raise SceneError(camera_path, f"{where}: give both cam_R_w2c and cam_t_w2c or neither")
        if has_r:
            rotation = _rotation(entry["cam_R_w2c"], camera_path, f"{where} cam_R_w2c")
            translation = _number_array(entry["cam_t_w2c"], 3, camera_path, f"{where} cam_t_w2c")
            poses[index] = invert_transform(make_transform(rotation, translation / 1000.0))
    if poses and len(poses) != len(ids):
        raise SceneError(
            camera_path,
            "camera poses are given for some frames but not all",
            "give cam_R_w2c and cam_t_w2c for every frame or for none",
        )

    images = []
    for index in ids:
        rgb = _read_rgb(rgb_files[index])
        units = _read_depth_units(depth_files[index])
        if rgb.shape[:2] != units.shape:
            raise SceneError(
                depth_files[index],
                f"depth is {units.shape[1]}x{units.shape[0]} but rgb is {rgb.shape[1]}x{rgb.shape[0]}",
                "rgb and depth of a frame must have the same size (register depth to colour)",
            )
        depth_m = units.astype(np.float32) * np.float32(scales[index] / 1000.0)
        valid = depth_m[depth_m > 0]
        if valid.size == 0:
            raise SceneError(
                depth_files[index],
                "depth image has no valid reading (all zero)",
                "check the depth export; 0 means no reading",
            )
        median = float(np.median(valid))
        if not PLAUSIBLE_DEPTH_M[0] <= median <= PLAUSIBLE_DEPTH_M[1]:
            raise SceneError(
                depth_files[index],
                f"median depth is {median:.3g} m with depth_scale {scales[index]:g} "
                f"(expected {PLAUSIBLE_DEPTH_M[0]}-{PLAUSIBLE_DEPTH_M[1]} m): likely a unit error",
                "set depth_scale to the millimetres per depth unit (1.0 for mm, 0.1 for 0.1 mm)",
            )
        mask = None
        if index in mask_files:
            mask = _read_mask(mask_files[index])
            if mask.shape != units.shape:
                raise SceneError(
                    mask_files[index],
                    f"mask is {mask.shape[1]}x{mask.shape[0]}, image is {units.shape[1]}x{units.shape[0]}",
                    "masks must have the size of the frame's images",
                )
        images.append((rgb, depth_m, mask))

    note = ""
    if poses:
        if up_camera is not None:
            raise SceneError(
                camera_path,
                "an up direction was given but the scene gives camera poses, which fix gravity",
                "leave out --up (up_camera) for scenes with cam_R_w2c/cam_t_w2c",
            )
        source = "camera_poses"
        world_from_camera = poses
    else:
        source = "support_plane"
        shared, note = world_from_support_plane(
            images[0][1],
            intrinsics[ids[0]],
            seed=plane_seed,
            path=depth_files[ids[0]],
            up_camera=up_camera,
            with_note=True,
        )
        world_from_camera = {index: shared for index in ids}

    frames = tuple(
        Frame(index, rgb, depth_m, intrinsics[index], world_from_camera[index], mask)
        for index, (rgb, depth_m, mask) in zip(ids, images, strict=True)
    )
    pusher, pushes = _load_actions(root / "actions.json", frames, has_poses=bool(poses))
    return Scene(root, frames, pushes, pusher, source, note)


def world_from_support_plane(
    depth_m: np.ndarray,
    K: np.ndarray,
    *,
    seed: int = 0,
    path: Path | str = "depth",
    up_camera: Sequence[float] | None = None,
    with_note: bool = False,
    choice: SupportChoiceConfig | None = None,
) -> np.ndarray | tuple[np.ndarray, str]:
    """World-from-camera (4, 4) built from the support of one depth image (contract rule).

    The support is the plane the objects rest on (``ipr.geometry.support.choose_support``): the
    largest plane, unless it is the tops of packed objects (the support is then the lowest
    level reached below them) or a floor seen beyond a table (the table). With ``up_camera``
    (the up direction in camera coordinates), only planes within ``UP_MAX_TILT_DEG`` of
    perpendicular to it are considered. z is the support's normal pointing towards the camera,
    the origin is the camera centre projected on the support, and x is the camera's x axis
    projected on it. With ``with_note``, returns (transform, a line saying which plane and why).

    Raises:
        SceneError: gravity cannot be determined (no plane holds a tenth of the points, or none
            is perpendicular to ``up_camera``, or the camera is below it), naming the frame and
            the fix.
    """
    points = backproject(depth_m, K)[depth_m > 0]
    up = None if up_camera is None else _up_direction(up_camera, path)
    plane = fit_plane_ransac(
        points,
        threshold_m=0.01,
        iterations=1000,
        min_inliers=max(500, len(points) // 10),
        rng=np.random.default_rng(seed),
        axis=up,
        max_tilt_deg=UP_MAX_TILT_DEG if up is not None else 90.0,
    )
    if plane is None:
        where = (
            f"no plane within {UP_MAX_TILT_DEG:g} degrees of perpendicular to the given up direction"
            if up is not None
            else "no plane"
        )
        raise SceneError(
            path,
            f"frame 0: cannot determine gravity: {where} holds a tenth of the frame's points "
            "and no camera pose is given",
            GRAVITY_FIX
            if up is None
            else "check --up (the up direction in camera "
            "coordinates, e.g. 0 -1 0 for a camera held level), or give the camera pose "
            "(cam_R_w2c, cam_t_w2c) in scene_camera.json",
        )
    if up is not None and float(plane.normal @ up) < 0:
        plane = Plane(-plane.normal, -plane.offset, plane.inliers)
    if up is not None and plane.offset <= 0:
        raise SceneError(
            path,
            "frame 0: the camera is below the support for the given up direction",
            "check the sign of --up (the up direction in camera coordinates; 0 -1 0 for a "
            "camera held level, looking down at the table)",
        )
    plane = plane.oriented_towards(np.zeros(3))
    grid = backproject(depth_m, K)
    usable = np.flatnonzero((depth_m > 0).ravel())
    chosen = choose_support(grid, usable, plane, np.zeros(3), choice or SupportChoiceConfig())
    if not chosen.is_dominant:
        log.info("%s: support: %s", path, chosen.reason)
    z_axis = np.asarray(chosen.normal, dtype=np.float64)
    origin = -chosen.offset * z_axis  # camera centre (0) projected on the plane
    x_axis = np.array([1.0, 0.0, 0.0]) - z_axis[0] * z_axis
    if np.linalg.norm(x_axis) < 1e-6:  # camera x axis along the normal: use its y axis instead
        x_axis = np.array([0.0, 1.0, 0.0]) - z_axis[1] * z_axis
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    camera_from_world = make_transform(np.column_stack([x_axis, y_axis, z_axis]), origin)
    world_from_camera = invert_transform(camera_from_world)
    if with_note:
        return world_from_camera, chosen.reason
    return world_from_camera


def _up_direction(value: Sequence[float], path: Path | str) -> np.ndarray:
    """A given up direction as a unit (3,) vector; SceneError when it is not 3 finite numbers
    or is the zero vector."""
    try:
        up = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        up = np.zeros(0)
    if up.size != 3 or not np.all(np.isfinite(up)) or np.linalg.norm(up) < 1e-9:
        raise SceneError(
            path,
            f"the up direction must be 3 finite numbers, not all zero; got {value!r}",
            "give the up direction in camera coordinates, e.g. --up 0 -1 0",
        )
    return up / np.linalg.norm(up)


def _load_actions(
    path: Path, frames: Sequence[Frame], *, has_poses: bool
) -> tuple[Pusher | None, tuple[Push, ...]]:
    if not path.exists():
        return None, ()
    actions = read_json(path, "actions.json")
    if not isinstance(actions, dict):
        raise SceneError(path, "actions.json must be a JSON object")
    tag = actions.get("format")
    if tag != ACTIONS_FORMAT:
        raise SceneError(path, f"unknown format {tag!r}", f'set "format": "{ACTIONS_FORMAT}"')
    frame_name = actions.get("frame", "world")
    if frame_name == "world":
        if not has_poses:
            raise SceneError(
                path,
                "actions are in the world frame but scene_camera.json gives no camera poses",
                'add cam_R_w2c/cam_t_w2c, or give actions in "camera:0" coordinates',
            )
        world_from_actions = np.eye(4)
    else:
        match = re.fullmatch(r"camera:(\d+)", str(frame_name))
        if not match or int(match.group(1)) >= len(frames):
            raise SceneError(
                path,
                f"unknown frame {frame_name!r}",
                'use "world" or "camera:<id>" with an existing frame id',
            )
        world_from_actions = frames[int(match.group(1))].world_from_camera

    rotation, translation = world_from_actions[:3, :3], world_from_actions[:3, 3]
    pusher_spec = actions.get("pusher", {})
    if not isinstance(pusher_spec, dict):
        raise SceneError(path, "'pusher' must be an object")
    shape = pusher_spec.get("shape", "capsule")
    if shape != "capsule":
        raise SceneError(path, f"pusher shape {shape!r} is not supported", 'use "capsule"')
    radius = _positive_number(pusher_spec.get("radius_m", 0.01), path, "pusher radius_m")
    length = _positive_number(pusher_spec.get("length_m", 0.15), path, "pusher length_m")
    if length < 2 * radius:
        raise SceneError(path, "pusher length_m is shorter than its two caps (2 x radius_m)")
    axis = _unit_vector(pusher_spec.get("axis", [0, 0, 1]), path, "pusher axis")
    pusher = Pusher(radius, length, rotation @ axis)

    pushes_spec = actions.get("pushes", [])
    if not isinstance(pushes_spec, list):
        raise SceneError(path, "'pushes' must be a list")
    pushes = []
    for number, spec in enumerate(pushes_spec):
        where = f"push {number}"
        if not isinstance(spec, dict):
            raise SceneError(path, f"{where} must be an object")
        for key in (
            "before_frame",
            "after_frame",
            "start_m",
            "direction",
            "distance_m",
            "speed_m_s",
        ):
            if key not in spec:
                raise SceneError(path, f"{where}: '{key}' is missing")
        before, after = spec["before_frame"], spec["after_frame"]
        for key, value in (("before_frame", before), ("after_frame", after)):
            if (
                isinstance(value, bool)
                or not isinstance(value, int)
                or not 0 <= value < len(frames)
            ):
                raise SceneError(
                    path,
                    f"{where}: {key} {value!r} names a frame that does not exist",
                    f"use frame ids 0..{len(frames) - 1}",
                )
        if after <= before:
            raise SceneError(path, f"{where}: after_frame must come after before_frame")
        start = _number_array(spec["start_m"], 3, path, f"{where} start_m")
        direction = _unit_vector(spec["direction"], path, f"{where} direction")
        distance = _positive_number(spec["distance_m"], path, f"{where} distance_m")
        speed = _positive_number(spec["speed_m_s"], path, f"{where} speed_m_s")
        pushes.append(
            Push(
                before, after, rotation @ start + translation, rotation @ direction, distance, speed
            )
        )
    pushes.sort(key=lambda push: push.before_frame)
    return pusher, tuple(pushes)


# --------------------------------------------------------------------------------------------
# Ground truth (evaluation only)


def load_ground_truth(path: Path | str) -> dict[int, list[ObjectPose]]:
    """``scene_gt.json`` of a scene: frame id -> object poses (camera from model, metres)."""
    gt_path = Path(path) / "scene_gt.json"
    if not gt_path.is_file():
        raise SceneError(
            gt_path,
            "this scene has no ground truth (scene_gt.json is missing)",
            "evaluation needs a scene with BOP ground truth, such as one made by 'ipr synth'",
        )
    raw = read_json(gt_path, "scene_gt.json")
    if not isinstance(raw, dict):
        raise SceneError(gt_path, "must map frame ids to lists of objects")
    result: dict[int, list[ObjectPose]] = {}
    for key, objects in raw.items():
        if not str(key).isdigit() or not isinstance(objects, list):
            raise SceneError(gt_path, f"entry {key!r} must be a frame id mapping to a list")
        poses = []
        for item in objects:
            if not isinstance(item, dict) or "obj_id" not in item:
                raise SceneError(
                    gt_path, f"frame {key}: each object needs obj_id, cam_R_m2c, cam_t_m2c"
                )
            rotation = _rotation(item.get("cam_R_m2c"), gt_path, f"frame {key} cam_R_m2c")
            translation = _number_array(item.get("cam_t_m2c"), 3, gt_path, f"frame {key} cam_t_m2c")
            poses.append(
                ObjectPose(int(item["obj_id"]), make_transform(rotation, translation / 1000))
            )
        result[int(key)] = poses
    return result


def load_visible_pixel_counts(path: Path | str) -> dict[int, list[int]] | None:
    """``px_count_visib`` per frame and object (order of ``scene_gt.json``), or None if absent."""
    info_path = Path(path) / "scene_gt_info.json"
    if not info_path.exists():
        return None
    raw = read_json(info_path, "scene_gt_info.json")
    try:
        return {
            int(key): [int(item["px_count_visib"]) for item in items] for key, items in raw.items()
        }
    except (AttributeError, KeyError, TypeError, ValueError):
        raise SceneError(info_path, "each object entry needs an integer px_count_visib") from None


def default_models_dir(scene_path: Path | str) -> Path:
    """Where the contract places BOP models for a scene: ``<scene>/../models``."""
    return Path(scene_path).resolve().parent / "models"


def load_model(models_dir: Path | str, obj_id: int):
    """BOP model ``obj_NNNNNN.ply`` (millimetres) as a trimesh in metres, model frame."""
    import trimesh

    model_path = Path(models_dir) / f"obj_{obj_id:06d}.ply"
    if not model_path.is_file():
        raise SceneError(
            model_path,
            f"model of object {obj_id} not found",
            "pass the BOP models folder with --models",
        )
    mesh = trimesh.load(model_path, force="mesh", process=False)
    mesh.apply_scale(0.001)
    return mesh


# --------------------------------------------------------------------------------------------
# Writing


def write_scene(
    path: Path | str,
    frames: Sequence[Frame],
    *,
    pushes: Sequence[Push] = (),
    pusher: Pusher | None = None,
    depth_scale: float = 1.0,
    write_poses: bool = True,
    ground_truth: dict[int, list[ObjectPose]] | None = None,
    ground_truth_info: dict[int, list[dict[str, Any]]] | None = None,
    overwrite: bool = False,
    extra_files: dict[str, bytes] | None = None,
) -> Path:
    """Write a scene directory per the contract, atomically (staged, then renamed into place).

    Depth is stored as uint16 ``round(depth_m * 1000 / depth_scale)``. Pushes are written in the
    world frame (``write_poses`` must then be True). ``extra_files`` maps relative paths (such as
    ``preview.png``) to bytes written alongside.
    """
    target = Path(path)
    if target.exists() and not overwrite:
        raise SceneError(target, "already exists", "choose another folder or allow overwriting")
    with staged_directory(target) as staging:
        (staging / "rgb").mkdir()
        (staging / "depth").mkdir()
        cameras: dict[str, Any] = {}
        for frame in frames:
            name = f"{frame.index:06d}.png"
            Image.fromarray(frame.rgb).save(staging / "rgb" / name)
            units = np.round(frame.depth_m.astype(np.float64) * 1000.0 / depth_scale)
            Image.fromarray(np.clip(units, 0, 65535).astype(np.uint16)).save(
                staging / "depth" / name
            )
            entry: dict[str, Any] = {
                "cam_K": frame.K.reshape(-1).tolist(),
                "depth_scale": depth_scale,
            }
            if write_poses:
                camera_from_world = invert_transform(frame.world_from_camera)
                entry["cam_R_w2c"] = camera_from_world[:3, :3].reshape(-1).tolist()
                entry["cam_t_w2c"] = (camera_from_world[:3, 3] * 1000.0).tolist()
            cameras[str(frame.index)] = entry
            if frame.robot_mask is not None:
                (staging / "mask_robot").mkdir(exist_ok=True)
                mask = frame.robot_mask.astype(np.uint8) * 255
                Image.fromarray(mask).save(staging / "mask_robot" / name)
        _write_json(staging / "scene_camera.json", cameras)
        if pushes or pusher is not None:
            if not write_poses:
                raise ValueError("pushes are written in the world frame, which needs camera poses")
            pusher = pusher or Pusher()
            _write_json(
                staging / "actions.json",
                {
                    "format": ACTIONS_FORMAT,
                    "frame": "world",
                    "pusher": {
                        "shape": "capsule",
                        "radius_m": pusher.radius_m,
                        "length_m": pusher.length_m,
                        "axis": pusher.axis.tolist(),
                    },
                    "pushes": [
                        {
                            "before_frame": push.before_frame,
                            "after_frame": push.after_frame,
                            "start_m": push.start_m.tolist(),
                            "direction": push.direction.tolist(),
                            "distance_m": push.distance_m,
                            "speed_m_s": push.speed_m_s,
                        }
                        for push in pushes
                    ],
                },
            )
        if ground_truth is not None:
            _write_json(
                staging / "scene_gt.json",
                {
                    str(index): [
                        {
                            "obj_id": pose.obj_id,
                            "cam_R_m2c": pose.camera_from_model[:3, :3].reshape(-1).tolist(),
                            "cam_t_m2c": (pose.camera_from_model[:3, 3] * 1000.0).tolist(),
                        }
                        for pose in poses
                    ]
                    for index, poses in sorted(ground_truth.items())
                },
            )
        if ground_truth_info is not None:
            _write_json(
                staging / "scene_gt_info.json",
                {str(index): items for index, items in sorted(ground_truth_info.items())},
            )
        for relative, content in (extra_files or {}).items():
            destination = staging / relative
            destination.parent.mkdir(parents=True, exist_ok=True)
            destination.write_bytes(content)
    return target


def _write_json(path: Path, content: Any) -> None:
    path.write_text(json.dumps(content, indent=1, allow_nan=False) + "\n", encoding="utf-8")
