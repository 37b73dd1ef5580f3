"""Pinhole camera geometry shared by every stage: OpenCV conventions, rigid transforms, MuJoCo cameras.

Conventions: camera frames are OpenCV's (x right, y down, z forward along the optical axis);
``K`` is the 3x3 intrinsic matrix in pixels with pixel centres at integer coordinates; transforms
are 4x4 homogeneous matrices named ``<to>_from_<from>`` in metres. MuJoCo cameras look along their
-z axis with y up, so their orientation is the OpenCV one turned by pi about x.
"""

from __future__ import annotations

import numpy as np

# OpenCV camera axes expressed in MuJoCo camera axes (and back): a rotation by pi about x.
MUJOCO_FROM_OPENCV = np.diag([1.0, -1.0, -1.0])


def make_transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Return the 4x4 transform from a (3, 3) rotation and a (3,) translation."""
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = translation
    return transform


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (rotation transposed, translation rotated back)."""
    rotation = transform[:3, :3]
    return make_transform(rotation.T, -rotation.T @ transform[:3, 3])


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (..., 3) points."""
    return points @ transform[:3, :3].T + transform[:3, 3]


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """World-from-camera (4, 4) transform (OpenCV camera, m) of a camera at ``eye`` looking at
    ``target`` ((3,) world points, m).

    ``up`` (3,) is the world direction that appears upward in the image; it must not be parallel
    to the viewing direction.
    """
    eye = np.asarray(eye, dtype=float)
    forward = np.asarray(target, dtype=float) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=float))
    norm = np.linalg.norm(right)
    if norm < 1e-9:
        raise ValueError("look_at: 'up' is parallel to the viewing direction")
    right /= norm
    down = np.cross(forward, right)
    return make_transform(np.column_stack([right, down, forward]), eye)


def backproject(depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points (H, W, 3) in metres from a (H, W) depth image (0 = no reading)."""
    height, width = depth_m.shape
    u = np.arange(width, dtype=np.float64)
    v = np.arange(height, dtype=np.float64)
    z = depth_m.astype(np.float64)
    x = (u[None, :] - K[0, 2]) / K[0, 0] * z
    y = (v[:, None] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=-1)


def backproject_pixels(
    pixels: np.ndarray, depth_m: np.ndarray, K: np.ndarray, width: int
) -> np.ndarray:
    """Camera-frame points (N, 3) in metres of (N,) flat pixel indices of an image ``width``
    pixels wide, at their (N,) depths (m); ``backproject`` for chosen pixels only."""
    rows, cols = np.divmod(np.asarray(pixels), width)
    z = np.asarray(depth_m, dtype=np.float64)
    return np.stack([(cols - K[0, 2]) / K[0, 0] * z, (rows - K[1, 2]) / K[1, 1] * z, z], axis=1)


def project(points_camera: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixel coordinates (N, 2) as (u, v) of (N, 3) camera-frame points with z > 0."""
    z = points_camera[:, 2]
    u = K[0, 0] * points_camera[:, 0] / z + K[0, 2]
    v = K[1, 1] * points_camera[:, 1] / z + K[1, 2]
    return np.stack([u, v], axis=-1)


def mujoco_camera_attributes(K: np.ndarray, width: int, height: int) -> dict[str, str]:
    """MJCF ``<camera>`` attributes that reproduce intrinsics ``K`` at ``width`` x ``height``.

    MuJoCo places its principal point relative to the image centre ((W-1)/2, (H-1)/2 in OpenCV
    pixel coordinates) with the sign measured in ``tests/test_camera.py``; the sensor size only
    scales focal lengths internally, so any positive value works.
    """
    sensor = (width * 1e-5, height * 1e-5)
    principal = ((width - 1) / 2.0 - K[0, 2], (height - 1) / 2.0 - K[1, 2])
    return {
        "resolution": f"{width} {height}",
        "sensorsize": f"{sensor[0]:.10g} {sensor[1]:.10g}",
        "focalpixel": f"{K[0, 0]:.10g} {K[1, 1]:.10g}",
        "principalpixel": f"{principal[0]:.10g} {principal[1]:.10g}",
    }


def mujoco_camera_pose(world_from_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo camera position (3,) and quaternion (4,) w-x-y-z for an OpenCV world-from-camera."""
    from scipy.spatial.transform import Rotation

    rotation = world_from_camera[:3, :3] @ MUJOCO_FROM_OPENCV
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return world_from_camera[:3, 3].copy(), np.array([w, x, y, z])


def view_halfspaces(
    K: np.ndarray, world_from_camera: np.ndarray, shape: tuple[int, int]
) -> np.ndarray:
    """The camera's view as four world half-spaces (4, 4): rows (n, b) with n . x + b >= 0 for
    world points x (m) that project inside the image of ``shape`` (height, width) pixels, one
    per border (left, right, top, bottom), unit n pointing into the view, so n . x + b is the
    distance (m) of x from that border's plane (through the camera centre), positive inside.

    The borders are the image's outer pixel edges (u = -0.5, u = width - 0.5 and likewise v;
    pixel centres at integer coordinates). Points behind the camera are not excluded: the sides
    alone bound what a frame cannot have seen beside it (``ipr_shapes.hypotheses.generate``).
    """
    height, width = shape
    K = np.asarray(K, dtype=float)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    # u = fx x / z + cx >= -0.5  <=>  fx x + (cx + 0.5) z >= 0 (z > 0), and likewise.
    normals = np.array(
        [
            [fx, 0.0, cx + 0.5],
            [-fx, 0.0, width - 0.5 - cx],
            [0.0, fy, cy + 0.5],
            [0.0, -fy, height - 0.5 - cy],
        ]
    )
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    transform = np.asarray(world_from_camera, dtype=float)
    world = normals @ transform[:3, :3].T
    return np.column_stack([world, -(world @ transform[:3, 3])])
