"""The support is the plane the objects rest on, not the largest plane (``ipr_shapes.geometry.support``):
a table seen with the floor around it, boxes packed in a bin whose floor is hidden, a plain
table; and the perception keeps the choice across frames."""

from __future__ import annotations

import numpy as np
import pytest

from ipr_shapes.camera import backproject, invert_transform, look_at
from ipr_shapes.geometry.planes import fit_plane_ransac
from ipr_shapes.geometry.support import choose_support

WIDTH, HEIGHT = 160, 120
K = np.array([[150.0, 0.0, WIDTH / 2 - 0.5], [0.0, 150.0, HEIGHT / 2 - 0.5], [0.0, 0.0, 1.0]])


def box(lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box (world, m) by its lower and upper corners."""
    return np.asarray(lower, float), np.asarray(upper, float)


def render(boxes, world_from_camera: np.ndarray, hidden: tuple[int, ...] = ()) -> np.ndarray:
    """Depth (H, W) m of axis-aligned boxes (slab ray casting); 0 where no box is hit, or where
    the nearest hit is one of the ``hidden`` boxes (a surface the sensor does not see)."""
    u, v = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(u.shape)], -1)
    directions = rays @ world_from_camera[:3, :3].T  # unit z in the camera: t is the depth
    origin = world_from_camera[:3, 3]
    nearest = np.full(u.shape, np.inf)
    which = np.full(u.shape, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for number, (lower, upper) in enumerate(boxes):
            t1 = (lower - origin) / directions
            t2 = (upper - origin) / directions
            near = np.nanmax(np.minimum(t1, t2), axis=-1)
            far = np.nanmin(np.maximum(t1, t2), axis=-1)
            hit = (near <= far) & (near > 0) & (near < nearest)
            nearest[hit] = near[hit]
            which[hit] = number
    depth = np.where(np.isfinite(nearest), nearest, 0.0)
    depth[np.isin(which, hidden)] = 0.0
    return depth.astype(np.float32)


def choose(depth: np.ndarray):
    """The support choice of a depth image in camera coordinates, from the dominant plane as
    the scene loader fits it; returns (choice, dominant plane)."""
    grid = backproject(depth, K)
    usable = np.flatnonzero((depth > 0).ravel())
    dominant = fit_plane_ransac(
        grid.reshape(-1, 3)[usable],
        threshold_m=0.01,
        iterations=1000,
        min_inliers=len(usable) // 10,
        rng=np.random.default_rng(0),
    ).oriented_towards(np.zeros(3))
    return choose_support(grid, usable, dominant, np.zeros(3)), dominant


def height_of(choice, world_from_camera: np.ndarray) -> tuple[float, float]:
    """The chosen plane in the world: (angle of its normal to +z in degrees, its height)."""
    camera_from_world = invert_transform(world_from_camera)
    normal_world = world_from_camera[:3, :3] @ choice.normal
    # A point of the plane in the camera frame, taken to the world.
    point = world_from_camera[:3, :3] @ (-choice.offset * choice.normal) + world_from_camera[:3, 3]
    assert np.allclose(camera_from_world @ world_from_camera, np.eye(4))
    return float(np.degrees(np.arccos(np.clip(normal_world[2], -1, 1)))), float(point[2])


# A table 0.6 x 0.4 m, its top at 0.5 m, on a 4 x 4 m floor, with two boxes on it; the floor
# around the table holds 71 % of the pixels, the table 19 %.
TABLE_SCENE = [
    box([-2, -2, -0.02], [2, 2, 0.0]),  # floor
    box([-0.3, -0.2, 0.47], [0.3, 0.2, 0.5]),  # table top
    box([-0.28, -0.18, 0.0], [-0.25, -0.15, 0.47]),  # legs
    box([0.25, -0.18, 0.0], [0.28, -0.15, 0.47]),
    box([-0.1, -0.05, 0.5], [0.0, 0.05, 0.62]),  # objects on the table
    box([0.08, -0.1, 0.5], [0.16, -0.02, 0.56]),
]
TABLE_CAMERA = look_at(np.array([0.0, -0.8, 1.0]), np.array([0.0, 0.0, 0.45]))


def test_a_floor_seen_around_a_table_is_not_the_support():
    depth = render(TABLE_SCENE, TABLE_CAMERA)
    choice, dominant = choose(depth)
    tilt, dominant_height = height_of(
        type(choice)(dominant.normal, dominant.offset, dominant.inliers, "", ""), TABLE_CAMERA
    )
    assert abs(dominant_height) < 0.01  # the largest plane is the floor ...
    assert choice.source == "upper level"  # ... but the objects rest on the table
    tilt, height = height_of(choice, TABLE_CAMERA)
    assert tilt < 2.0 and height == pytest.approx(0.5, abs=0.01)
    assert "stand on it" in choice.reason


# A bin 0.40 x 0.30 m with 12 cm walls; boxes 5 cm tall packed in it with 1 cm gaps; the bin's
# floor is at 0.02 (its bottom is 2 cm thick), on a floor at 0.
def bin_scene(gap: float = 0.01) -> list:
    scene = [
        box([-1, -1, -0.02], [1, 1, 0.0]),  # floor outside
        box([-0.2, -0.15, 0.0], [0.2, 0.15, 0.02]),  # the bin's bottom
        box([-0.21, -0.16, 0.0], [-0.2, 0.16, 0.14]),  # walls
        box([0.2, -0.16, 0.0], [0.21, 0.16, 0.14]),
        box([-0.21, -0.16, 0.0], [0.21, -0.15, 0.14]),
        box([-0.21, 0.15, 0.0], [0.21, 0.16, 0.14]),
    ]
    x_edges = np.linspace(-0.2 + gap, 0.2 - gap, 5)
    y_edges = np.linspace(-0.15 + gap, 0.15 - gap, 4)
    for x0, x1 in zip(x_edges[:-1], x_edges[1:], strict=True):
        for y0, y1 in zip(y_edges[:-1], y_edges[1:], strict=True):
            scene.append(
                box([x0 + gap / 2, y0 + gap / 2, 0.02], [x1 - gap / 2, y1 - gap / 2, 0.07])
            )
    return scene


BIN_CAMERA = look_at(np.array([0.0, -0.2, 0.45]), np.array([0.0, 0.0, 0.04]))


@pytest.mark.parametrize("floor_seen", [True, False])
def test_the_tops_of_boxes_packed_in_a_bin_are_not_the_support(floor_seen: bool):
    """The bin's floor shows in the gaps, or (a black floor the sensor does not see) not at
    all: the support is then just under the lowest sides of the boxes seen."""
    depth = render(bin_scene(), BIN_CAMERA, hidden=() if floor_seen else (1,))
    choice, dominant = choose(depth)
    _, top = height_of(
        type(choice)(dominant.normal, dominant.offset, dominant.inliers, "", ""), BIN_CAMERA
    )
    assert top == pytest.approx(0.07, abs=0.01)  # the largest plane is the boxes' tops
    assert choice.source == "below tops"
    tilt, height = height_of(choice, BIN_CAMERA)
    assert tilt < 2.0
    assert 0.0 <= height <= 0.03  # under every box (bottoms at 0.02), above the outside floor


def test_a_table_with_objects_keeps_the_largest_plane_exactly():
    scene = [
        box([-0.5, -0.4, -0.03], [0.5, 0.4, 0.0]),
        box([-0.1, -0.05, 0.0], [0.0, 0.05, 0.12]),
        box([0.08, -0.1, 0.0], [0.16, -0.02, 0.06]),
    ]
    camera = look_at(np.array([0.0, -0.5, 0.5]), np.array([0.0, 0.0, 0.0]))
    choice, dominant = choose(render(scene, camera))
    assert choice.is_dominant
    assert np.array_equal(choice.normal, dominant.normal)
    assert choice.offset == dominant.offset
    assert choice.inliers is dominant.inliers


def test_no_choice_without_candidates():
    from ipr_shapes.geometry.support import SupportChoiceConfig

    depth = render(TABLE_SCENE, TABLE_CAMERA)
    grid = backproject(depth, K)
    usable = np.flatnonzero((depth > 0).ravel())
    dominant = fit_plane_ransac(grid.reshape(-1, 3)[usable], rng=np.random.default_rng(0))
    choice = choose_support(grid, usable, dominant, np.zeros(3), SupportChoiceConfig(candidates=0))
    assert choice.is_dominant


def test_scene_and_perception_agree_on_the_table_and_keep_it_in_later_frames(tmp_path):
    """Without camera poses, the loader builds the world on the table (not the floor); the
    perception finds the same support in frame 0 and keeps it in frame 1."""
    from ipr_shapes.perception.config import PerceptionConfig
    from ipr_shapes.perception.planes import find_support_plane
    from ipr_shapes.scene import Frame, load_scene, write_scene

    depth = render(TABLE_SCENE, TABLE_CAMERA)
    rgb = np.full((HEIGHT, WIDTH, 3), 128, np.uint8)
    frames = [Frame(i, rgb, depth, K, TABLE_CAMERA) for i in range(2)]
    scene = load_scene(write_scene(tmp_path / "s", frames, write_poses=False))
    assert "stand on it" in scene.support_note
    frame = scene.frames[0]
    points = frame.points_world()
    table = np.abs(points[..., 2]) < 0.005
    assert table.sum() > 1000  # the table top is at world z = 0
    config = PerceptionConfig()
    usable = np.flatnonzero((frame.depth_m > 0).ravel())
    flat = points.reshape(-1, 3)[usable]
    first = find_support_plane(
        flat,
        config,
        grid=points,
        usable=usable,
        viewpoint=frame.world_from_camera[:3, 3],
    )
    assert first.normal[2] > 0.999 and abs(first.offset) < 0.005
    later = find_support_plane(
        flat,
        config,
        grid=points,
        usable=usable,
        viewpoint=frame.world_from_camera[:3, 3],
        previous=first,
    )
    assert later is first  # the largest plane (the floor) is not the earlier support
    alone = find_support_plane(flat, config)  # no grid: the largest plane, as before
    assert alone.offset > 0.4  # the floor, 0.5 m below the table


def test_candidate_pieces_are_found_when_read_and_are_the_large_pieces_of_their_mask():
    # The support choice reads only some candidates' pieces (the dominant plane's and the
    # walls' when the dominant plane is the tops of objects): each is found when first read,
    # and is _largest_piece of the candidate's mask with the configured share.
    from ipr_shapes.geometry.support import SupportChoiceConfig, _candidates, _largest_piece

    depth = render(bin_scene(), BIN_CAMERA)
    grid = backproject(depth, K)
    _, dominant = choose(depth)
    config = SupportChoiceConfig(piece_share=0.01)
    valid = depth > 0  # the analysis grid at full resolution (a 160-column image)
    flat_valid = np.flatnonzero(valid.ravel())
    points = grid.reshape(-1, 3)[flat_valid]
    candidates = _candidates(points, flat_valid, valid.shape, dominant, np.zeros(3), config)
    assert len(candidates) >= 3
    assert all("piece" not in vars(candidate) for candidate in candidates)
    for candidate in candidates:
        expected = _largest_piece(candidate.mask, 0.01)
        np.testing.assert_array_equal(candidate.piece, expected)
        assert "piece" in vars(candidate)  # kept once found
    # The share matters here (small pieces kept at 0.01, only the largest at 1.0).
    assert any(not np.array_equal(_largest_piece(c.mask, 1.0), c.piece) for c in candidates)
