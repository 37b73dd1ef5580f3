"""Pieces of one thin cylinder joined (``ipr_shapes.perception.thin``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.thin import cylinder_fit, join_thin_pieces
from ipr_shapes.perception.types import Supervoxels

K = np.array([[600.0, 0.0, 80.0], [0.0, 600.0, 60.0], [0.0, 0.0, 1.0]])
HEIGHT, WIDTH = 120, 160
BACKGROUND_M = 0.6
RGB = np.full((HEIGHT, WIDTH, 3), 120, dtype=np.uint8)


def _rays() -> np.ndarray:
    """(H, W, 3) camera rays with unit z (the camera frame is the world frame here)."""
    rows, cols = np.mgrid[:HEIGHT, :WIDTH]
    return np.stack(
        [(cols - K[0, 2]) / K[0, 0], (rows - K[1, 2]) / K[1, 1], np.ones((HEIGHT, WIDTH))], -1
    )


def _cylinder_depth(centre_y: float, centre_z: float, radius: float, x_range: tuple) -> np.ndarray:
    """(H, W) depth of a cylinder along the camera's x axis (inf where the ray misses it)."""
    rays = _rays()
    # (t y' - yc)^2 + (t - zc)^2 = r^2 with t the depth.
    a = rays[..., 1] ** 2 + 1.0
    b = -2.0 * (rays[..., 1] * centre_y + centre_z)
    c = centre_y**2 + centre_z**2 - radius**2
    disc = b**2 - 4 * a * c
    t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a), np.inf)
    x = rays[..., 0] * np.where(np.isfinite(t), t, 0.0)
    return np.where((x >= x_range[0]) & (x <= x_range[1]), t, np.inf)


def _scene(depths: list[np.ndarray], noise_m: float = 0.001, seed: int = 0):
    """Labels, depth and points of objects given by their depth images (nearest wins), before
    a plane at ``BACKGROUND_M`` (label 0). Object k is label k + 1."""
    stack = np.stack([np.full((HEIGHT, WIDTH), BACKGROUND_M), *depths])
    nearest = np.argmin(stack, axis=0)
    depth = np.take_along_axis(stack, nearest[None], axis=0)[0]
    depth = depth + np.random.default_rng(seed).normal(0.0, noise_m, depth.shape)
    points = _rays() * depth[..., None]
    return nearest.astype(np.int32), depth, points


def _supervoxels(labels: np.ndarray) -> Supervoxels:
    count = int(labels.max()) + 1
    return Supervoxels(
        labels - 1,
        np.zeros((count, 3)),
        np.tile([0.0, 0.0, -1.0], (count, 1)),
        np.zeros((count, 3)),
        np.ones(count),
        np.zeros((0, 2), dtype=np.int64),
    )


def _thin(radius_m: float = 0.0125) -> PerceptionConfig:
    """The default configuration with the thin-cylinder join at ``radius_m`` (0: off)."""
    base = PerceptionConfig()
    return dataclasses.replace(
        base, segmentation=dataclasses.replace(base.segmentation, thin_radius_m=radius_m)
    )


def _join(labels, depth, points, config=None):
    segments = np.arange(1, int(labels.max()) + 1, dtype=np.int32)
    return join_thin_pieces(
        labels,
        segments,
        points,
        depth,
        K,
        RGB,
        _supervoxels(labels),
        np.zeros(3),
        config or _thin(),
    )


def _split_along_x(labels: np.ndarray, points: np.ndarray, label: int, at_m: float, new: int):
    """``label``'s pixels with world x above ``at_m`` relabelled ``new`` (a cut across it)."""
    out = labels.copy()
    out[(labels == label) & (points[..., 0] > at_m)] = new
    return out


def test_cylinder_fit_recovers_a_marker_and_refuses_a_flat_strip():
    rng = np.random.default_rng(1)
    angle = rng.uniform(-1.4, 1.4, 400)  # the half a camera sees
    along = rng.uniform(0.0, 0.1, 400)
    radius = 0.008
    # Axis along x at 0.5 m from a camera at the origin, looking along z.
    marker = np.stack([along, radius * np.sin(angle), 0.5 - radius * np.cos(angle)], 1)
    fitted, rms = cylinder_fit(marker + rng.normal(0.0, 0.0005, marker.shape), np.zeros(3))
    assert fitted == pytest.approx(radius, abs=0.001)
    assert rms < 0.001
    for width in (0.04, 0.012):
        strip = np.stack(
            [along, rng.uniform(-width / 2, width / 2, 400), 0.5 + rng.normal(0, 0.0005, 400)], 1
        )
        fitted, rms = cylinder_fit(strip, np.zeros(3))
        assert fitted > 0.02 or rms > 0.003  # a flat strip is no thin cylinder
    inside = marker * [1.0, 1.0, -1.0] + [0.0, 0.0, 1.0]  # the hollow of a half pipe
    assert cylinder_fit(inside, np.zeros(3)) == (np.inf, np.inf)


def test_a_marker_cut_in_three_becomes_one_segment_and_other_labels_stay():
    marker = _cylinder_depth(0.0, 0.5, 0.008, (-0.05, 0.05))
    block = np.where(_rays()[..., 1] > 0.03, 0.45, np.inf)  # a flat face below it in the image
    labels, depth, points = _scene([marker, block])
    labels = _split_along_x(labels, points, 1, -0.015, 3)
    labels = _split_along_x(labels, points, 3, 0.02, 4)
    assert set(np.unique(labels)) == {0, 1, 2, 3, 4}
    joined, segments = _join(labels, depth, points)
    on_marker = np.isin(labels, [1, 3, 4])
    assert len(np.unique(joined[on_marker])) == 1
    np.testing.assert_array_equal(joined[labels == 2], 2)
    assert segments.tolist()[1] == 2 and len(set(segments[[0, 2, 3]].tolist())) == 1


def test_two_markers_side_by_side_stay_apart():
    first = _cylinder_depth(-0.008, 0.5, 0.008, (-0.05, 0.05))
    second = _cylinder_depth(0.008, 0.5, 0.008, (-0.05, 0.05))
    labels, depth, points = _scene([first, second])
    joined, _ = _join(labels, depth, points)
    np.testing.assert_array_equal(joined, labels)


def test_a_marker_lying_against_a_box_stays_apart():
    marker = _cylinder_depth(0.0, 0.5, 0.008, (-0.05, 0.05))
    # A box face at the marker's axis depth, just above it in the image: they touch.
    box = np.where((_rays()[..., 1] < -0.016) & (_rays()[..., 1] > -0.06), 0.5, np.inf)
    labels, depth, points = _scene([marker, box])
    joined, _ = _join(labels, depth, points)
    np.testing.assert_array_equal(joined, labels)


@pytest.mark.parametrize("radius", [0.033, 0.016])
def test_a_wider_cylinder_cut_in_two_is_not_thin_and_the_join_can_be_switched_off(radius):
    # A can (3.3 cm) and a cylinder slender enough to be a candidate but wider than the
    # 12.5 mm of a thin object: the graph's business, not this join's.
    can = _cylinder_depth(0.0, 0.5, radius, (-0.05, 0.05))
    labels, depth, points = _scene([can])
    labels = _split_along_x(labels, points, 1, 0.0, 2)
    joined, _ = _join(labels, depth, points)
    np.testing.assert_array_equal(joined, labels)
    marker = _cylinder_depth(0.0, 0.5, 0.008, (-0.05, 0.05))
    labels, depth, points = _scene([marker])
    labels = _split_along_x(labels, points, 1, 0.0, 2)
    assert len(np.unique(_join(labels, depth, points)[0])) == 2  # joined: background + 1
    np.testing.assert_array_equal(_join(labels, depth, points, _thin(0.0))[0], labels)
    # On by default (docs/DESIGN_NOTES.md, "Thin cylinders joined").
    assert len(np.unique(_join(labels, depth, points, PerceptionConfig())[0])) == 2


def test_a_marker_cut_lengthwise_is_not_joined_its_pieces_must_lie_end_to_end():
    # The two halves of its seen surface run side by side along the axis: the cut this join
    # repairs goes across (each supervoxel spans a thin cylinder's width), and two pieces side
    # by side along one axis are what an object lying along a marker looks like.
    marker = _cylinder_depth(0.0, 0.5, 0.008, (-0.05, 0.05))
    labels, depth, points = _scene([marker])
    labels[(labels == 1) & (points[..., 1] > 0.0)] = 2
    joined, _ = _join(labels, depth, points)
    np.testing.assert_array_equal(joined, labels)


def test_a_flat_patch_at_a_markers_tip_stays_apart():
    # A small flat patch (a box's corner) 4 mm before the marker's tip.
    marker = _cylinder_depth(0.0, 0.5, 0.008, (-0.05, 0.05))
    rays = _rays()
    patch_x = rays[..., 0] * 0.488
    patch = np.where(
        (patch_x > 0.05) & (patch_x < 0.054) & (np.abs(rays[..., 1] * 0.488) < 0.008),
        0.488,
        np.inf,
    )
    labels, depth, points = _scene([marker, patch], noise_m=0.0005)
    joined, _ = _join(labels, depth, points)
    np.testing.assert_array_equal(joined, labels)


def test_borders_shared_from_the_fragments_pass_give_the_same_join():
    # segment_frame hands the fragments' border pass to the thin join when no fragment joined:
    # its area and touching counts must be those of the thin join's own pass.
    from ipr_shapes.perception.fragments import fragment_borders, segment_borders

    marker = _cylinder_depth(0.0, 0.5, 0.008, (-0.05, 0.05))
    block = np.where(_rays()[..., 1] > 0.03, 0.45, np.inf)
    labels, depth, points = _scene([marker, block])
    labels = _split_along_x(labels, points, 1, -0.015, 3)
    labels = _split_along_x(labels, points, 3, 0.02, 4)
    config = _thin()
    # The pieces' normals 60 degrees apart: beyond the fragments' bend, so the fragments'
    # continuous counts are not the thin join's contacts (any normals).
    supervoxels = _supervoxels(labels)
    tilted = [0.0, np.sin(np.radians(60.0)), -np.cos(np.radians(60.0))]
    supervoxels.normals[2] = tilted  # label 3's supervoxel
    assert config.segmentation.fragment_bend_deg < 60.0
    shared = fragment_borders(labels, points, depth, K, RGB, supervoxels, config)
    own = segment_borders(
        labels, points, depth, K, RGB, supervoxels, config.segmentation.fragment_gap_m, 180.0
    )
    np.testing.assert_array_equal(shared[0], own[0])
    np.testing.assert_array_equal(shared[4], own[4])
    np.testing.assert_array_equal(own[4], own[3])  # any normals: touching is continuous
    assert shared[3][1, 3] == 0 and shared[4][1, 3] > 0  # the bend matters for continuous
    segments = np.arange(1, int(labels.max()) + 1, dtype=np.int32)
    arguments = (labels, segments, points, depth, K, RGB, supervoxels, np.zeros(3), config)
    with_shared, _ = join_thin_pieces(*arguments, borders=shared)
    alone, _ = join_thin_pieces(*arguments)
    np.testing.assert_array_equal(with_shared, alone)
    assert len(np.unique(alone[alone > 0])) < len(np.unique(labels[labels > 0]))
    np.testing.assert_array_equal(shared[4], own[4])  # the shared counts are not modified
