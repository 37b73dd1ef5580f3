"""Free space: never inside a real object, free in front of surfaces, unknown behind them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ipr_shapes import voxels
from ipr_shapes.perception.free_space import FREE, OCCUPIED, UNKNOWN, VoxelGrid, observe_space
from ipr_shapes.scene import default_models_dir, load_ground_truth, load_model, load_scene
from ipr_shapes.synth import SynthConfig, generate_scene


@pytest.fixture(scope="module")
def generated_scene(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("free_space")
    return generate_scene(
        out, kind="static", seed=11, arrangement="table", config=SynthConfig(width=320, height=240)
    )


@pytest.mark.slow  # generates a full scene (7 s): runs in .ci/run's slow stage
def test_space_inside_ground_truth_objects_is_never_free(generated_scene: Path):
    scene = load_scene(generated_scene)
    frame = scene.frames[0]
    grid = VoxelGrid.around([-0.35, -0.35, -0.05], [0.35, 0.35, 0.35])
    space = observe_space(frame.depth_m, frame.K, frame.world_from_camera, grid)
    models = default_models_dir(generated_scene)
    inside_states = []
    for pose in load_ground_truth(generated_scene)[0]:
        world_from_model = frame.world_from_camera @ pose.camera_from_model
        keys = voxels.occupied_voxels(load_model(models, pose.obj_id), 0.005, world_from_model)
        inside_states.append(space.state_at(voxels.centres(keys, 0.005)))
    states = np.concatenate(inside_states)
    assert states.size > 1000
    assert np.count_nonzero(states == FREE) == 0
    # The visible skin of the objects is seen as occupied, the rest is hidden (unknown).
    assert np.count_nonzero(states == OCCUPIED) > 0.05 * states.size
    assert np.count_nonzero(states == UNKNOWN) > 0.3 * states.size


@pytest.mark.slow  # generates a full scene (7 s): runs in .ci/run's slow stage
def test_free_in_front_of_surfaces_and_unknown_behind(generated_scene: Path):
    frame = load_scene(generated_scene).frames[0]
    grid = VoxelGrid.around([-0.35, -0.35, -0.05], [0.35, 0.35, 0.35])
    space = observe_space(frame.depth_m, frame.K, frame.world_from_camera, grid)
    # Points on valid rays: 60 % of the way from the camera to the observed surface are free,
    # 5 cm beyond the surface are unknown (hidden).
    rows, cols = np.nonzero(frame.depth_m > 0)
    pick = np.random.default_rng(0).choice(rows.size, 400, replace=False)
    surface = frame.points_world()[rows[pick], cols[pick]]
    camera = frame.world_from_camera[:3, 3]
    in_grid = np.all(
        (surface > grid.origin + 0.06)
        & (surface < grid.origin + np.array(grid.shape) * 0.005 - 0.06),
        axis=1,
    )
    surface = surface[in_grid]
    direction = (surface - camera) / np.linalg.norm(surface - camera, axis=1, keepdims=True)
    before = surface - 0.4 * (surface - camera)
    before = before[np.all(before < grid.origin + np.array(grid.shape) * 0.005, axis=1)]
    behind = surface + 0.05 * direction
    assert np.mean(space.state_at(before) == FREE) > 0.95
    assert np.mean(space.state_at(behind) == UNKNOWN) > 0.9
    assert np.mean(space.state_at(surface) == OCCUPIED) > 0.8


def test_missing_depth_and_ignored_pixels_are_never_free():
    K = np.array([[100.0, 0, 39.5], [0, 100.0, 29.5], [0, 0, 1]])
    world_from_camera = np.eye(4)
    depth = np.full((60, 80), 1.0, dtype=np.float32)
    depth[:, :40] = 0  # no reading on the left half
    grid = VoxelGrid.around([-0.3, -0.2, 0.3], [0.3, 0.2, 0.9])
    space = observe_space(depth, K, world_from_camera, grid)
    left = np.array([[-0.1, 0.0, 0.5]])
    right = np.array([[0.1, 0.0, 0.5]])
    assert space.state_at(left)[0] == UNKNOWN
    assert space.state_at(right)[0] == FREE
    ignore = np.zeros_like(depth, dtype=bool)
    ignore[:, 40:] = True
    assert (
        observe_space(depth, K, world_from_camera, grid, ignore_mask=ignore).state_at(right)[0]
        == UNKNOWN
    )


def test_grid_is_aligned_to_the_metrics_lattice():
    grid = VoxelGrid.around([-0.0123, 0.004, 0.1], [0.05, 0.05, 0.2], 0.005)
    assert np.allclose(grid.origin / 0.005, np.round(grid.origin / 0.005))
    centres = grid.centres()
    assert np.allclose((centres[0, 0, 0] / 0.005) % 1, 0.5)


def test_state_at_is_the_lookup_of_the_grid_indices():
    """The compiled ``state_at`` reads the voxel ``grid.indices_of`` gives (numpy's floor of
    the same quotient), UNKNOWN outside the grid; points on voxel faces, just inside and
    outside each face of the grid, far away and not finite."""
    from ipr_shapes.perception.free_space import SpaceMap, VoxelGrid

    rng = np.random.default_rng(11)
    grid = VoxelGrid(np.array([-0.1, 0.2, -0.03]), 0.005, (30, 20, 12))
    space = SpaceMap(grid, rng.integers(0, 3, grid.shape).astype(np.uint8))
    low, high = grid.origin, grid.origin + np.array(grid.shape) * grid.voxel_size_m
    inside = rng.uniform(low, high, (2000, 3))
    faces = grid.origin + rng.integers(-2, 35, (500, 3)) * grid.voxel_size_m
    edges = np.concatenate([low + 1e-12, high - 1e-12, low - 1e-12, high + 1e-12]).reshape(-1, 3)
    odd = np.array([[np.nan, 0.25, 0.0], [np.inf, 0.25, 0.0], [1e300, 0.0, 0.0]])
    points = np.concatenate([inside, faces, edges, odd, rng.normal(0.0, 3.0, (200, 3))])
    with np.errstate(invalid="ignore", over="ignore"):  # numpy's cast of the far points
        indices, kept = grid.indices_of(np.nan_to_num(points, nan=1e9))
    expected = np.zeros(len(points), np.uint8)
    expected[kept] = space.state[tuple(indices[kept].T)]
    got = space.state_at(points)
    assert got.dtype == np.uint8 and np.array_equal(got, expected)
    single = points[np.abs(points).max(axis=1) < 1e30].astype(np.float32)
    assert np.array_equal(space.state_at(single), space.state_at(single.astype(np.float64)))
    assert (got > 0).sum() > 1000 and space.state_at(np.zeros((0, 3))).shape == (0,)
