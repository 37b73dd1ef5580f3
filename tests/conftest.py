"""Shared fixtures: small scenes written through the real scene writer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ipr_shapes.camera import look_at
from ipr_shapes.data import shared_data_dir
from ipr_shapes.scene import Frame, Push, Pusher, write_scene


def plane_depth(K: np.ndarray, world_from_camera: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Exact depth (m) of the plane z = 0 seen by a camera, with a 6 cm box-like bump in the middle."""
    height, width = shape
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1)
    rays_world = rays @ world_from_camera[:3, :3].T
    origin = world_from_camera[:3, 3]
    depth = -origin[2] / rays_world[..., 2]  # planar z: rays have unit z in the camera frame
    points = origin + depth[..., None] * rays_world
    bump = (np.abs(points[..., 0]) < 0.03) & (np.abs(points[..., 1]) < 0.03)
    depth[bump] -= 0.03
    return np.where(depth > 0, depth, 0).astype(np.float32)


def make_frames(count: int = 2, size: tuple[int, int] = (120, 160)) -> list[Frame]:
    """Frames of a table plane seen from 0.6 m at about 45 degrees."""
    height, width = size
    K = np.array([[150.0, 0, width / 2 - 0.5], [0, 150.0, height / 2 - 0.5], [0, 0, 1]])
    world_from_camera = look_at(np.array([0.0, -0.45, 0.45]), np.zeros(3))
    rng = np.random.default_rng(0)
    frames = []
    for index in range(count):
        rgb = rng.integers(0, 255, size=(height, width, 3), dtype=np.uint8)
        depth = plane_depth(K, world_from_camera, (height, width))
        frames.append(Frame(index, rgb, depth, K, world_from_camera))
    return frames


@pytest.fixture
def scene_dir(tmp_path: Path) -> Path:
    """A valid two-frame dynamic scene with camera poses and one push."""
    frames = make_frames(2)
    push = Push(0, 1, np.array([-0.1, 0.0, 0.08]), np.array([1.0, 0, 0]), 0.08, 0.05)
    return write_scene(tmp_path / "scene", frames, pushes=[push], pusher=Pusher())


@pytest.fixture
def shared_data() -> Path:
    """The shared data folder; tests that need it skip when it is absent."""
    root = shared_data_dir()
    if root is None:
        pytest.skip("shared data (../shared/data or $IPR_DATA) is absent")
    return root
