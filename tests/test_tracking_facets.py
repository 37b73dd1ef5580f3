"""Tracking keeps ids through pushes and relabelling; facets split objects by normals and gaps."""

from __future__ import annotations

import numpy as np

from ipr.perception.facets import mean_shift_directions, object_facets, pixel_areas
from ipr.perception.tracking import track_segments


def _frame(squares: dict[int, tuple[int, int, tuple[int, int, int]]], shape=(80, 120)):
    """Label image, world points (1 px = 1 mm on a plane) and colours for coloured squares."""
    labels = np.zeros(shape, np.int32)
    rgb = np.full((*shape, 3), 128, np.uint8)
    for label, (row, col, colour) in squares.items():
        labels[row : row + 15, col : col + 15] = label
        rgb[row : row + 15, col : col + 15] = colour
    v, u = np.mgrid[: shape[0], : shape[1]]
    points = np.stack([u * 0.001, v * 0.001, np.zeros(shape)], axis=-1)
    return labels, points, rgb


RED, GREEN, BLUE, YELLOW = (200, 30, 30), (30, 200, 30), (30, 30, 200), (220, 220, 20)


def test_ids_survive_relabelling_motion_disappearance_and_new_objects():
    first = _frame({1: (10, 10, RED), 2: (10, 50, GREEN), 3: (50, 90, BLUE)})
    # Segment numbers permuted, green pushed by 25 mm, blue gone, a yellow object appears.
    second = _frame({5: (10, 10, RED), 1: (20, 75, GREEN), 2: (55, 20, YELLOW)})
    # Blue comes back where it was; red gone.
    third = _frame({1: (10, 75, GREEN), 4: (50, 90, BLUE), 3: (55, 20, YELLOW)})
    tracked = track_segments(*map(list, zip(first, second, third, strict=True)))
    red, green, blue = (tracked[0][r, c] for r, c in ((12, 12), (12, 52), (52, 92)))
    assert sorted([red, green, blue]) == [1, 2, 3]
    assert tracked[1][12, 12] == red and tracked[1][22, 77] == green
    yellow = tracked[1][57, 22]
    assert yellow not in (red, green, blue)
    assert (
        tracked[2][12, 77] == green and tracked[2][52, 92] == blue and tracked[2][57, 22] == yellow
    )


def test_same_colour_objects_are_told_apart_by_position():
    first = _frame({1: (10, 10, RED), 2: (10, 80, RED)})
    second = _frame({1: (12, 82, RED), 2: (12, 8, RED)})  # numbers swapped, small motions
    tracked = track_segments(*map(list, zip(first, second, strict=True)))
    assert tracked[1][14, 10] == tracked[0][12, 12]
    assert tracked[1][14, 84] == tracked[0][12, 82]


def test_mean_shift_groups_normals_by_direction():
    rng = np.random.default_rng(0)
    up = np.array([0, 0, 1.0]) + rng.normal(0, 0.03, (20, 3))
    side = np.array([1.0, 0, 0]) + rng.normal(0, 0.03, (15, 3))
    normals = np.vstack([up, side])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    labels = mean_shift_directions(normals, np.ones(len(normals)), bandwidth=0.35)
    assert len(set(labels[:20])) == 1 and len(set(labels[20:])) == 1 and labels[0] != labels[20]


def test_box_seen_from_above_gives_top_and_side_facets_with_areas():
    # Supervoxels of a 10 cm box: 4 on the top (normal +z), 2 on the front (normal -y), 1 on a
    # separate, parallel plane (another top, not connected) -> 3 facets.
    normals = np.array([[0, 0, 1]] * 4 + [[0, -1, 0]] * 2 + [[0, 0, 1]], dtype=float)
    sizes = np.array([10, 10, 10, 10, 8, 8, 5])
    adjacency = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]])
    point_supervoxel = np.repeat(np.arange(7), sizes)
    points = np.random.default_rng(1).uniform(0, 0.1, (len(point_supervoxel), 3))
    areas = np.full(len(points), 1e-4)
    facets, facet_of_point = object_facets(
        np.arange(7), normals, sizes, adjacency, point_supervoxel, points, areas, bandwidth=0.35
    )
    assert len(facets) == 3
    by_size = sorted(facets, key=lambda f: -f.area_m2)
    assert np.allclose(by_size[0].normal, [0, 0, 1]) and by_size[0].area_m2 == np.float64(40e-4)
    assert np.allclose(by_size[1].normal, [0, -1, 0]) and by_size[1].area_m2 == np.float64(16e-4)
    assert (facet_of_point >= 0).all()


def test_pixel_area_of_a_fronto_parallel_and_a_tilted_plane():
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    point = np.array([[0.0, 0.0, 1.0]])
    flat = pixel_areas(point, np.array([[0, 0, -1.0]]), K)[0]
    assert np.isclose(flat, 1.0 / 500**2)
    tilted_normal = np.array([[0, np.sin(np.pi / 3), -np.cos(np.pi / 3)]])
    assert np.isclose(pixel_areas(point, tilted_normal, K)[0], flat / np.cos(np.pi / 3))
