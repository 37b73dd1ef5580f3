"""Offscreen rendering: analytic depth and id masks of boxes seen by a known pinhole camera."""

import numpy as np
import pytest
import trimesh

from ipr_shapes.camera import look_at
from ipr_shapes.rendering import Renderer, render_depth_and_ids

pytest.importorskip("mujoco")

WIDTH, HEIGHT = 160, 120
K = np.array([[200.0, 0.0, 79.5], [0.0, 200.0, 59.5], [0.0, 0.0, 1.0]])


def _translation(x: float, y: float, z: float) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, 3] = [x, y, z]
    return transform


@pytest.fixture(scope="module")
def renderer():
    with Renderer(WIDTH, HEIGHT) as shared:
        yield shared


def test_box_depth_and_mask_are_analytic(renderer):
    # Camera at z = -1 looking along +z (OpenCV): a 10 cm cube at the origin shows its face
    # z = -0.05 at depth 0.95 m, spanning u, v = c -+ f * 0.05 / 0.95.
    world_from_camera = _translation(0.0, 0.0, -1.0)
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    depth, index = render_depth_and_ids(
        [box], [np.eye(4)], K, WIDTH, HEIGHT, world_from_camera, renderer=renderer
    )
    assert depth.shape == (HEIGHT, WIDTH) and depth.dtype == np.float32
    assert index.shape == (HEIGHT, WIDTH) and index.dtype == np.int32
    assert depth[60, 80] == pytest.approx(0.95, abs=1e-5)
    half = 200.0 * 0.05 / 0.95
    rows, cols = np.nonzero(index == 0)
    assert (cols.min(), cols.max()) == (int(np.ceil(79.5 - half)), int(np.floor(79.5 + half)))
    assert (rows.min(), rows.max()) == (int(np.ceil(59.5 - half)), int(np.floor(59.5 + half)))
    assert np.allclose(depth[index == 0], 0.95, atol=1e-5)  # the face is fronto-parallel
    assert np.all(depth[index < 0] == 0.0)
    assert set(np.unique(index)) == {-1, 0}


def test_off_centre_oblique_camera_and_occlusion(renderer):
    # Two boxes on the optical axis of an oblique camera: the nearer hides part of the farther.
    eye = np.array([0.4, -0.3, 0.5])
    world_from_camera = look_at(eye, np.zeros(3))
    axis = -eye / np.linalg.norm(eye)
    near_centre = eye + 0.5 * axis
    far_centre = np.zeros(3)
    small = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    large = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    poses = [_translation(*far_centre), _translation(*near_centre)]
    depth, index = render_depth_and_ids(
        [large, small], poses, K, WIDTH, HEIGHT, world_from_camera, renderer=renderer
    )
    # The principal point (79.5, 59.5) lies between four pixels, all on the near box.
    assert np.all(index[59:61, 79:81] == 1)
    assert (index == 0).sum() > (index == 1).sum() > 0
    # Depth on the near box: the camera-frame z of its surface is within its half-diagonal.
    near_z = 0.5
    assert np.all(np.abs(depth[index == 1] - near_z) <= 0.01 * np.sqrt(3) + 1e-6)
    assert depth[index == 0].min() > near_z


def test_open_and_tiny_meshes_render_and_renderer_is_reusable(renderer):
    world_from_camera = _translation(0.0, 0.0, -1.0)
    quad = (
        np.array([[-0.1, -0.1, 0], [0.1, -0.1, 0], [0.1, 0.1, 0], [-0.1, 0.1, 0]]),
        np.array([[0, 1, 2], [0, 2, 3]]),
    )
    triangle = (
        np.array([[-0.3, -0.2, -0.1], [-0.2, -0.2, -0.1], [-0.3, -0.1, -0.1]]),
        np.array([[0, 1, 2]]),
    )
    empty = (np.zeros((0, 3)), np.zeros((0, 3), dtype=int))
    meshes = [quad, empty, triangle]
    depth, index = render_depth_and_ids(
        meshes, [None, None, None], K, WIDTH, HEIGHT, world_from_camera, renderer=renderer
    )
    assert depth[60, 80] == pytest.approx(1.0, abs=1e-5)  # open quad, seen from either side
    assert (index == 0).sum() > 0 and (index == 1).sum() == 0 and (index == 2).sum() > 0
    # A fresh renderer gives the same images as the shared, reused one.
    fresh_depth, fresh_index = render_depth_and_ids(
        meshes, [None, None, None], K, WIDTH, HEIGHT, world_from_camera
    )
    assert np.array_equal(fresh_index, index) and np.array_equal(fresh_depth, depth)


def test_renderer_size_mismatch_is_rejected(renderer):
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    with pytest.raises(ValueError, match="renderer is"):
        render_depth_and_ids([box], [None], K, 320, 240, _translation(0, 0, -1), renderer=renderer)
