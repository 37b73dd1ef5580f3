"""Scene directories (``SCENE_FORMAT.md``, contract version 1): read, validate, write.

A scene is a BOP scene folder (``scene_camera.json``, ``rgb/``, ``depth/``) plus optional robot
pushes (``actions.json``) and robot masks (``mask_robot/``). Everything in memory is in metres, in
the world frame (z up, gravity -z) or the frame's OpenCV camera frame; millimetres exist only in
the files. Ground truth (``scene_gt.json``, models) is read by separate functions that only
evaluation and benchmarks call: inference never reads it.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import re
import stat
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from ipr_shapes import voxels
from ipr_shapes.atomic import staged_directory
from ipr_shapes.camera import backproject, invert_transform, make_transform
from ipr_shapes.errors import SceneError
from ipr_shapes.geometry.planes import Plane, fit_plane_ransac
from ipr_shapes.geometry.support import SupportChoiceConfig, choose_support

log = logging.getLogger(__name__)

ACTIONS_FORMAT = "ipr-actions/1"
FRAME_NAME = re.compile(r"^(\d{6})\.(png|jpg|jpeg)$")
#: Plausible range of the median valid depth of a frame (m); outside it the depth scale is
#: almost certainly in the wrong unit.
PLAUSIBLE_DEPTH_M = (0.1, 5.0)
#: Tolerance on |direction| = 1 and on rotation orthonormality.
UNIT_TOLERANCE = 1e-3
#: A vector this close to length 1 is unit to float64 rounding (a norm's three products and
#: sum round by a few ulps) and is kept as given.
UNIT_ROUNDING = 8 * float(np.finfo(np.float64).eps)
#: Plausible ``depth_scale`` (mm per depth unit): 1.0 for millimetre PNGs, 0.1 for 0.1 mm; far
#: outside it the depths underflow or overflow.
PLAUSIBLE_DEPTH_SCALE = (1e-3, 100.0)
#: Largest image accepted (pixels a side, pixels in all), checked from the file header before
#: decoding: bigger images are refused instead of exhausting memory.
MAX_IMAGE_SIDE_PX = 8192
MAX_IMAGE_PIXELS = 4096 * 4096
#: Focal lengths (px) relative to the image width: about 2 to 157 degrees of field of view.
PLAUSIBLE_FOCAL_PER_WIDTH = (0.2, 30.0)
#: The principal point lies within the image grown by this share of its size on every side.
PRINCIPAL_POINT_MARGIN = 0.5
#: Largest distance (m) of a camera or ground-truth object from the origin (``ipr_shapes.voxels``):
#: a table-top scene is far smaller; beyond it the numbers are in the wrong unit or corrupt.
MAX_DISTANCE_M = voxels.MAX_DISTANCE_M
#: A camera pose must leave at least this share of the frame's depth points below the camera
#: (world z): the support (at least a tenth of the points) is below a camera that sees it.
MIN_SHARE_BELOW_CAMERA = 0.1
#: Plausible pushes: speed (m/s) and distance (m) of the pusher's centre; the replay time of
#: a slower push is capped by ``PhysicsConfig.push_max_s``.
PLAUSIBLE_PUSH_SPEED_M_S = (1e-3, 1.0)
PLAUSIBLE_PUSH_DISTANCE_M = (1e-4, 1.0)
#: Largest JSON file read (bytes): scene files of thousands of frames are a few megabytes.
MAX_JSON_BYTES = 64 * 1024 * 1024
#: Deepest nesting of numbers in a JSON value (cam_K may be a list of 3 lists).
_MAX_NUMBER_DEPTH = 3
#: Frame ids are written as six digits in file names.
MAX_FRAME_ID = 999_999
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
        from ipr_shapes.geometry.kernels import world_points

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
    ``support_note`` then says which plane that was and why (``ipr_shapes.geometry.support``).
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


def frames_digest(frames: Sequence[Frame]) -> str:
    """A fingerprint of the frames read (ids, colour and depth pixels, intrinsics): equal for
    the same captures wherever the folder is, so a result can tell its scene from another
    (``result.json``'s ``provenance.frames_digest``). 16 hex digits of SHA-256."""
    import hashlib

    digest = hashlib.sha256()
    for frame in frames:
        digest.update(str(int(frame.index)).encode())
        for array in (frame.rgb, frame.depth_m, frame.K):
            digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()[:16]


def file_kind(path: Path) -> str | None:
    """None when ``path`` is a regular file (through symlinks), else what it is instead:
    "missing", "a folder", "a named pipe (FIFO)", "a symlink loop", ... (for error messages;
    nothing is opened, so a FIFO cannot block)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return "a broken symlink" if path.is_symlink() else "missing"
    except OSError as error:
        if error.errno == errno.ELOOP:
            return "a symlink loop"
        if error.errno == errno.ENOTDIR:
            return "missing"
        return f"unreadable ({error.strerror})"
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a device"


def require_file(path: Path, what: str, fix: str = "") -> None:
    """SceneError unless ``path`` is a regular file, saying what it is instead."""
    kind = file_kind(path)
    if kind == "missing":
        raise SceneError(path, f"{what} is missing", fix or f"create {path.name}")
    if kind is not None:
        raise SceneError(
            path, f"{what} is {kind}, not a regular file", f"replace it with the {what} file"
        )


def read_json(path: Path, what: str) -> Any:
    """Parse a JSON file, rejecting NaN/Infinity literals; SceneError on any problem (missing
    or not a regular file, larger than ``MAX_JSON_BYTES``, nested too deeply, not UTF-8)."""
    require_file(path, what, f"create {path.name} as the contract says")

    def reject_constant(name: str) -> Any:
        raise SceneError(path, f"{what} contains {name}", "write finite numbers only")

    try:
        if path.stat().st_size > MAX_JSON_BYTES:
            raise SceneError(
                path,
                f"{what} is larger than {MAX_JSON_BYTES // 2**20} MiB",
                "check that this is the right file",
            )
        text = path.read_text(encoding="utf-8")
        return json.loads(text, parse_constant=reject_constant)
    except json.JSONDecodeError as error:
        raise SceneError(
            path,
            f"{what} is not valid JSON: {error.msg} at line {error.lineno} column {error.colno}",
            "correct the JSON syntax",
        ) from None
    except RecursionError:
        raise SceneError(path, f"{what} is nested too deeply", "write plain JSON") from None
    except UnicodeDecodeError:
        raise SceneError(path, f"{what} is not UTF-8 text", "save it as UTF-8 JSON") from None
    except OSError as error:
        raise SceneError(path, f"{what} cannot be read: {error.strerror}") from None


def is_number(value: Any) -> bool:
    """True for a JSON number: an int or float, not a bool (a Python int subclass) or string;
    numpy's integer and float scalars count too (``ipr_shapes.from_arrays``; JSON never gives them)."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _flat_numbers(value: Any) -> list | None:
    """The numbers of a number or of (nested, at most ``_MAX_NUMBER_DEPTH``) lists of numbers,
    flattened; None when anything else (a string, a bool, null, an object) is in it."""
    flat: list = []
    stack = [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if is_number(item):
            flat.append(item)
        elif isinstance(item, np.ndarray) and item.dtype.kind in "iuf":
            flat.extend(item.ravel().tolist())  # from ipr_shapes.from_arrays; JSON gives lists
        elif isinstance(item, list | tuple) and depth < _MAX_NUMBER_DEPTH:
            stack.extend((element, depth + 1) for element in reversed(item))
        else:
            return None
    return flat


def _number_array(value: Any, count: int, path: Path, key: str) -> np.ndarray:
    """A finite float64 array of ``count`` numbers (nested lists are flattened)."""
    flat = _flat_numbers(value)
    if flat is None:
        shown = repr(value) if len(repr(value)) < 80 else repr(value)[:77] + "..."
        raise SceneError(
            path,
            f"'{key}' must be a list of {count} numbers, got {shown}",
            "write numbers without quotes (no strings, true/false or null)",
        )
    try:
        array = np.asarray(flat, dtype=np.float64).reshape(-1)
    except OverflowError:
        raise SceneError(path, f"'{key}' holds a number too large") from None
    if array.size != count:
        raise SceneError(path, f"'{key}' must hold {count} numbers, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise SceneError(path, f"'{key}' contains NaN or inf", "write finite numbers only")
    return array


def _positive_number(value: Any, path: Path, key: str) -> float:
    if not is_number(value):
        raise SceneError(path, f"'{key}' must be a number, got {value!r}")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number) or number <= 0:
        raise SceneError(path, f"'{key}' must be positive and finite, got {value}")
    return number


def _unit_vector(value: Any, path: Path, key: str) -> np.ndarray:
    """``value`` as a unit (3,) vector, within ``UNIT_TOLERANCE`` of length 1. A vector already
    of length 1 to float64 rounding is kept bit for bit: dividing it by its norm again moves
    its last bits, and a replayed push is chaotic: the generator's recorded pushes must replay
    exactly (DESIGN_NOTES, "The replay ladder on the benchmark page")."""
    vector = _number_array(value, 3, path, key)
    norm = float(np.linalg.norm(vector))
    if norm < 1e-9:
        raise SceneError(path, f"'{key}' is the zero vector", "give a unit direction")
    if abs(norm - 1.0) > UNIT_TOLERANCE:
        raise SceneError(
            path, f"'{key}' is not a unit vector (length {norm:.4f})", "normalise it to length 1"
        )
    if abs(norm - 1.0) <= UNIT_ROUNDING:
        return vector
    return vector / norm


def _frame_files(folder: Path, allowed: tuple[str, ...]) -> dict[int, Path]:
    """Frame id -> file in ``folder`` (``NNNNNN.ext``); other files are ignored. A frame's
    entry that is not a regular file (a folder, a FIFO, a broken link) is refused here, before
    anything opens it."""
    files: dict[int, Path] = {}
    if not folder.is_dir():
        return files
    for entry in sorted(folder.iterdir()):
        match = FRAME_NAME.match(entry.name)
        if match and match.group(2) in allowed:
            index = int(match.group(1))
            if index in files:
                raise SceneError(
                    entry,
                    f"frame {index} has two files in {folder.name}/ ({files[index].name} and "
                    f"{entry.name})",
                    "keep one file per frame",
                )
            kind = file_kind(entry)
            if kind is not None:
                raise SceneError(
                    entry,
                    f"frame {index}'s image is {kind}, not a regular file",
                    "replace it with the image file",
                )
            files[index] = entry
    return files


def frame_ids(keys: Iterable[str], path: Path) -> dict[int, str]:
    """Frame id -> its key, from the keys of a BOP file (``scene_camera.json``): decimal
    integers 0..999999 in any order; two keys naming one id ("0" and "00") are refused."""
    ids: dict[int, str] = {}
    for key in keys:
        if not re.fullmatch(r"[0-9]{1,6}", key):
            raise SceneError(
                path,
                f"key {key!r} is not a frame id",
                f'use frame ids 0..{MAX_FRAME_ID} written as decimal integers, such as "0"',
            )
        index = int(key)
        if index in ids:
            raise SceneError(
                path,
                f'keys "{ids[index]}" and "{key}" both name frame {index} (rgb/{index:06d}.png)',
                "keep one entry per frame",
            )
        ids[index] = key
    if not ids:
        raise SceneError(path, "no frames", 'add an entry per frame, such as "0"')
    return ids


def parse_frame_selection(text: str) -> tuple[int, ...]:
    """Frame ids of a ``--frames`` selection: comma-separated ids and inclusive ranges
    ``A-B`` or ``A-B:STEP`` (``0,5,10``, ``0-20:5``, ``3-``... not allowed). ValueError on a
    malformed selection."""
    chosen: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        match = re.fullmatch(r"([0-9]{1,6})(?:-([0-9]{1,6})(?::([0-9]{1,6}))?)?", part)
        if not match:
            raise ValueError(
                f"--frames: {part!r} is not a frame id or range (use e.g. 0,5,10 or 0-20:5)"
            )
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) else first
        step = int(match.group(3)) if match.group(3) else 1
        if last < first or step < 1:
            raise ValueError(f"--frames: {part!r} is an empty range (use A-B with A <= B)")
        chosen.update(range(first, last + 1, step))
    return tuple(sorted(chosen))


def _check_selection(ids: list[int], selection: Sequence[int] | None, path: Path) -> list[int]:
    """The frame ids to read: ``selection`` (each must exist) or every id, in id order."""
    if selection is None:
        return ids
    wanted = sorted(set(int(index) for index in selection))
    missing = sorted(set(wanted) - set(ids))
    if not wanted or missing:
        raise SceneError(
            path,
            f"the chosen frames {missing[:10] or wanted} are not in the scene "
            f"(its frames: {_id_summary(ids)})",
            "choose frames the scene has (--frames)",
        )
    return wanted


def _id_summary(ids: Sequence[int]) -> str:
    shown = ", ".join(str(index) for index in ids[:8])
    return shown + (f", ... ({len(ids)} frames)" if len(ids) > 8 else "")


def _open_image(path: Path, what: str, fix: str):
    """A PIL image of ``path`` with only its header read; SceneError when it cannot be read or
    is larger than ``MAX_IMAGE_SIDE_PX`` / ``MAX_IMAGE_PIXELS`` (checked before decoding)."""
    too_large = SceneError(
        path,
        f"{what} claims more than {MAX_IMAGE_PIXELS // 2**20} Mpx; at most {MAX_IMAGE_SIDE_PX} "
        f"pixels a side and {MAX_IMAGE_PIXELS // 2**20} Mpx are accepted",
        "scale the images down (and cam_K with them)",
    )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            image = Image.open(path)
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise too_large from None
    except Exception as error:  # PIL raises many types on corrupt files
        raise SceneError(path, f"cannot read {what}: {error}", fix) from None
    width, height = image.size
    if (
        max(width, height) > MAX_IMAGE_SIDE_PX
        or width * height > MAX_IMAGE_PIXELS
        or min(width, height) < 1
    ):
        image.close()
        raise SceneError(
            path,
            f"{what} is {width}x{height} pixels; at most {MAX_IMAGE_SIDE_PX} pixels a side and "
            f"{MAX_IMAGE_PIXELS // 2**20} Mpx are accepted",
            "scale the images down (and cam_K with them)",
        )
    return image


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) of an image from its header (size limits checked)."""
    with _open_image(path, "image", "write a valid PNG/JPEG") as image:
        return image.size


def _decode(image, path: Path, what: str, fix: str) -> np.ndarray:
    try:
        image.load()
        return np.asarray(image)
    except Exception as error:  # truncated or corrupt data: PIL raises many types
        raise SceneError(path, f"cannot read {what}: {error}", fix) from None


def _read_rgb(path: Path) -> np.ndarray:
    fix = "write a valid PNG/JPEG"
    with _open_image(path, "RGB image", fix) as image:
        if image.mode not in ("RGB", "RGBA", "L", "P"):
            raise SceneError(path, f"RGB image has mode {image.mode}", "save 8-bit RGB")
        _decode(image, path, "RGB image", fix)
        return np.asarray(image.convert("RGB"), dtype=np.uint8)


def _read_depth_units(path: Path) -> np.ndarray:
    fix = "write a 16-bit PNG"
    with _open_image(path, "depth image", fix) as image:
        array = _decode(image, path, "depth image", fix)
        mode = image.mode
    if array.ndim != 2 or array.dtype not in (np.uint16, np.int32) or mode == "L":
        raise SceneError(
            path,
            f"depth must be a single-channel 16-bit PNG, got mode {mode} dtype {array.dtype}",
            "save depth as uint16 PNG with depth in mm = value x depth_scale",
        )
    if array.dtype == np.int32:  # PIL opens some 16-bit PNGs as 32-bit integers
        if array.min() < 0 or array.max() > 65535:
            raise SceneError(path, "depth values outside the 16-bit range", "save as uint16 PNG")
        array = array.astype(np.uint16)
    return array


def _read_mask(path: Path) -> np.ndarray:
    with _open_image(path, "mask", "write a PNG mask") as image:
        _decode(image, path, "mask", "write a PNG mask")
        return np.asarray(image.convert("L")) > 0


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
    path: Path | str,
    *,
    plane_seed: int = 0,
    up_camera: Sequence[float] | None = None,
    frames: Sequence[int] | None = None,
) -> Scene:
    """Read and validate a scene directory; raise SceneError naming the file and the fix.

    The world frame comes from the camera poses when every frame has one; otherwise the camera is
    taken as static and the world frame is built from the support found in frame 0
    (``world_from_support_plane``: z = the support's normal towards the camera, origin = the
    camera centre projected on it, x = the camera's x axis projected on it). ``up_camera``
    (3 numbers, any length) is the up direction in camera coordinates, for scenes without camera
    poses whose gravity the data cannot tell: the support is then the plane the objects rest on
    among the planes within 45 degrees of perpendicular to it (``UP_MAX_TILT_DEG``).

    Frame ids are any non-negative integers (BOP scenes may be sparse or start at 1); frames
    are in id order and keep their ids. ``frames`` chooses the ids to read (None: all); the
    first chosen frame is the reference ("frame 0" of the contract). Pushes name frames by id
    (``_load_actions``).
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
    keys = frame_ids(cameras, camera_path)
    camera_ids = {index: cameras[key] for index, key in keys.items()}
    all_ids = sorted(camera_ids)

    rgb_files = _frame_files(root / "rgb", ("png", "jpg", "jpeg"))
    depth_files = _frame_files(root / "depth", ("png",))
    for folder, files in (("rgb", rgb_files), ("depth", depth_files)):
        if not (root / folder).is_dir():
            raise SceneError(
                root / folder, f"{folder}/ folder is missing", "add one image per frame"
            )
        if sorted(files) != all_ids:
            missing = sorted(set(all_ids) - set(files))
            extra = sorted(set(files) - set(all_ids))
            problem = (
                f"has no image of frames {missing[:10]} listed in scene_camera.json"
                if missing
                else f"has frames {extra[:10]} that scene_camera.json does not list"
            )
            raise SceneError(
                root / folder,
                f"{folder}/ {problem}",
                "give one image per frame listed in scene_camera.json",
            )
    ids = _check_selection(all_ids, frames, camera_path)
    mask_files = _frame_files(root / "mask_robot", ("png",))

    intrinsics, scales, poses = {}, {}, {}
    for index in all_ids:
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
        scale = _positive_number(entry["depth_scale"], camera_path, f"{where} depth_scale")
        if not PLAUSIBLE_DEPTH_SCALE[0] <= scale <= PLAUSIBLE_DEPTH_SCALE[1]:
            raise SceneError(
                camera_path,
                f"{where}: depth_scale {scale:g} mm per depth unit is implausible (expected "
                f"{PLAUSIBLE_DEPTH_SCALE[0]:g}-{PLAUSIBLE_DEPTH_SCALE[1]:g})",
                "set depth_scale to the millimetres per depth unit (1.0 for mm, 0.1 for 0.1 mm)",
            )
        scales[index] = scale
        has_r, has_t = "cam_R_w2c" in entry, "cam_t_w2c" in entry
        if has_r != has_t:
            raise SceneError(camera_path, f"{where}: give both cam_R_w2c and cam_t_w2c or neither")
        if has_r:
            rotation = _rotation(entry["cam_R_w2c"], camera_path, f"{where} cam_R_w2c")
            translation = _number_array(entry["cam_t_w2c"], 3, camera_path, f"{where} cam_t_w2c")
            pose = invert_transform(make_transform(rotation, translation / 1000.0))
            if np.linalg.norm(pose[:3, 3]) > MAX_DISTANCE_M:
                raise SceneError(
                    camera_path,
                    f"{where}: the camera is {np.linalg.norm(pose[:3, 3]):.3g} m from the world "
                    f"origin (more than {MAX_DISTANCE_M:g} m)",
                    "give cam_t_w2c in millimetres",
                )
            poses[index] = pose
    if poses and len(poses) != len(all_ids):
        raise SceneError(
            camera_path,
            "camera poses are given for some frames but not all",
            "give cam_R_w2c and cam_t_w2c for every frame or for none",
        )
    for index in ids:
        _check_intrinsics(intrinsics[index], image_size(rgb_files[index]), camera_path, index)

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
        valid = depth_m[units > 0]
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
        if index in poses:
            _check_gravity(depth_m, intrinsics[index], poses[index], camera_path, index)
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
        world_from_camera = {index: shared for index in all_ids}

    chosen = tuple(
        Frame(index, rgb, depth_m, intrinsics[index], world_from_camera[index], mask)
        for index, (rgb, depth_m, mask) in zip(ids, images, strict=True)
    )
    pusher, pushes = _load_actions(
        root / "actions.json", world_from_camera, ids, has_poses=bool(poses)
    )
    return Scene(root, chosen, pushes, pusher, source, note)


def _check_intrinsics(K: np.ndarray, size: tuple[int, int], path: Path, index: int) -> None:
    """SceneError unless ``K`` is plausible for a ``size`` (width, height) image: focal lengths
    within ``PLAUSIBLE_FOCAL_PER_WIDTH`` of the width and of each other's order, principal
    point within the image grown by ``PRINCIPAL_POINT_MARGIN``, skew below the focal length."""
    width, height = size
    fx, fy, cx, cy, skew = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    low, high = PLAUSIBLE_FOCAL_PER_WIDTH
    fix = "give cam_K in pixels of this image: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
    for name, focal in (("fx", fx), ("fy", fy)):
        if not low * width <= focal <= high * width:
            raise SceneError(
                path,
                f"frame {index}: cam_K {name} = {focal:.4g} px is implausible for a "
                f"{width} px wide image (expected {low:g}-{high:g} x the width)",
                fix,
            )
    if not 0.5 <= fx / fy <= 2.0 or abs(skew) > 0.1 * fx:
        raise SceneError(
            path, f"frame {index}: cam_K fx/fy or skew is implausible (pixels far from square)", fix
        )
    margin = PRINCIPAL_POINT_MARGIN
    if not (-margin * width <= cx <= (1 + margin) * width) or not (
        -margin * height <= cy <= (1 + margin) * height
    ):
        raise SceneError(
            path,
            f"frame {index}: cam_K principal point ({cx:.4g}, {cy:.4g}) px lies far outside "
            f"the {width}x{height} image",
            fix,
        )


def _check_gravity(
    depth_m: np.ndarray, K: np.ndarray, world_from_camera: np.ndarray, path: Path, index: int
) -> None:
    """SceneError when a camera pose puts almost everything the camera sees above it: world z
    then does not point up (``MIN_SHARE_BELOW_CAMERA``), e.g. an identity or a camera-to-world
    rotation given as cam_R_w2c. Checked on every 4th pixel (cheap)."""
    sub = depth_m[::4, ::4]
    rows, cols = np.nonzero(sub > 0)
    if rows.size == 0:
        return
    u, v = cols * 4.0, rows * 4.0
    z = sub[rows, cols].astype(np.float64)
    rays = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z])
    height_above_camera = world_from_camera[2, :3] @ rays  # world z of point minus camera's
    share = float(np.mean(height_above_camera < 0))
    if share < MIN_SHARE_BELOW_CAMERA:
        raise SceneError(
            path,
            f"frame {index}: with its cam_R_w2c only {100 * share:.0f} % of what the camera sees "
            "lies below it, so world z does not point up (gravity is -z)",
            "give cam_R_w2c as the world-to-camera rotation of a world with z up",
        )


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

    The support is the plane the objects rest on (``ipr_shapes.geometry.support.choose_support``): the
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
    path: Path,
    world_from_camera: dict[int, np.ndarray],
    chosen: Sequence[int],
    *,
    has_poses: bool,
) -> tuple[Pusher | None, tuple[Push, ...]]:
    """The pusher and the pushes of ``actions.json`` in the world frame.

    ``before_frame``/``after_frame`` are frame ids (keys of ``scene_camera.json``). Of the
    ``chosen`` frames' pushes, those with both frames chosen are kept; those outside the chosen
    span are dropped; a push within the span with a frame not chosen is refused (the chosen
    frames would show its effect without it). Speeds and distances must be plausible
    (``PLAUSIBLE_PUSH_SPEED_M_S``, ``PLAUSIBLE_PUSH_DISTANCE_M``).
    """
    if not path.exists() and not path.is_symlink():
        return None, ()
    all_ids = sorted(world_from_camera)
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
        match = re.fullmatch(r"camera:([0-9]{1,6})", str(frame_name))
        if not match or int(match.group(1)) not in world_from_camera:
            raise SceneError(
                path,
                f"unknown frame {frame_name!r}",
                'use "world" or "camera:<id>" with an existing frame id',
            )
        world_from_actions = world_from_camera[int(match.group(1))]

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
            if not isinstance(value, int) or isinstance(value, bool) or value not in all_ids:
                raise SceneError(
                    path,
                    f"{where}: {key} {value!r} names a frame that does not exist",
                    f"use frame ids of scene_camera.json ({_id_summary(all_ids)})",
                )
        if after <= before:
            raise SceneError(path, f"{where}: after_frame must come after before_frame")
        start = _number_array(spec["start_m"], 3, path, f"{where} start_m")
        if np.linalg.norm(start) > MAX_DISTANCE_M:
            raise SceneError(
                path,
                f"{where}: start_m is {np.linalg.norm(start):.3g} m from the origin",
                "give start_m in metres",
            )
        direction = _unit_vector(spec["direction"], path, f"{where} direction")
        distance = _positive_number(spec["distance_m"], path, f"{where} distance_m")
        speed = _positive_number(spec["speed_m_s"], path, f"{where} speed_m_s")
        for name, value, (low, high), unit in (
            ("distance_m", distance, PLAUSIBLE_PUSH_DISTANCE_M, "m"),
            ("speed_m_s", speed, PLAUSIBLE_PUSH_SPEED_M_S, "m/s"),
        ):
            if not low <= value <= high:
                raise SceneError(
                    path,
                    f"{where}: {name} {value:.3g} {unit} is implausible for a robot push "
                    f"(expected {low:g}-{high:g} {unit})",
                    f"give {name} in {unit}",
                )
        inside = before in chosen and after in chosen
        if not inside and before < chosen[-1] and after > chosen[0]:
            raise SceneError(
                path,
                f"{where} (frame {before} -> {after}) happens between the chosen frames "
                f"but frame {before if before not in chosen else after} is not chosen",
                "choose both frames of every push between the chosen frames (--frames), or "
                "only frames before the first push",
            )
        if not inside:
            continue
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
            "evaluation needs a scene with BOP ground truth, such as one made by 'ipr-shapes synth'",
        )
    raw = read_json(gt_path, "scene_gt.json")
    if not isinstance(raw, dict):
        raise SceneError(gt_path, "must map frame ids to lists of objects")
    result: dict[int, list[ObjectPose]] = {}
    for key, objects in raw.items():
        if not re.fullmatch(r"[0-9]{1,6}", str(key)) or not isinstance(objects, list):
            raise SceneError(gt_path, f"entry {key!r} must be a frame id mapping to a list")
        poses = []
        for item in objects:
            if not isinstance(item, dict) or "obj_id" not in item:
                raise SceneError(
                    gt_path, f"frame {key}: each object needs obj_id, cam_R_m2c, cam_t_m2c"
                )
            obj_id = item["obj_id"]
            if (
                not isinstance(obj_id, int)
                or isinstance(obj_id, bool)
                or not 0 <= obj_id <= 999_999
            ):
                raise SceneError(
                    gt_path,
                    f"frame {key}: obj_id {obj_id!r} is not an object id",
                    "give obj_id as a whole number 0..999999 (the model obj_NNNNNN.ply)",
                )
            rotation = _rotation(item.get("cam_R_m2c"), gt_path, f"frame {key} cam_R_m2c")
            translation = _number_array(item.get("cam_t_m2c"), 3, gt_path, f"frame {key} cam_t_m2c")
            if np.linalg.norm(translation) > MAX_DISTANCE_M * 1000:
                raise SceneError(
                    gt_path,
                    f"frame {key}: object {obj_id} is {np.linalg.norm(translation) / 1000:.3g} m "
                    f"from the camera (more than {MAX_DISTANCE_M:g} m)",
                    "give cam_t_m2c in millimetres",
                )
            poses.append(ObjectPose(obj_id, make_transform(rotation, translation / 1000)))
        result[int(key)] = poses
    return result


def load_visible_pixel_counts(path: Path | str) -> dict[int, list[int]] | None:
    """``px_count_visib`` per frame and object (order of ``scene_gt.json``), or None if absent."""
    info_path = Path(path) / "scene_gt_info.json"
    if not info_path.exists():
        return None
    raw = read_json(info_path, "scene_gt_info.json")
    problem = SceneError(
        info_path,
        "each object entry needs px_count_visib, a whole number of pixels "
        f"0..{MAX_IMAGE_PIXELS}, under a frame id",
        "regenerate scene_gt_info.json (BOP toolkit)",
    )
    if not isinstance(raw, dict):
        raise problem
    counts: dict[int, list[int]] = {}
    for key, items in raw.items():
        if not re.fullmatch(r"[0-9]{1,6}", key) or not isinstance(items, list):
            raise problem
        row = []
        for item in items:
            value = item.get("px_count_visib") if isinstance(item, dict) else None
            if not is_number(value) or not 0 <= value <= MAX_IMAGE_PIXELS or value != int(value):
                raise problem
            row.append(int(value))
        counts[int(key)] = row
    return counts


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
