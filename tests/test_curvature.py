"""Concave edges on smoothly curved surfaces (``ipr_shapes.perception.curvature``) and the
workspace test (``ipr_shapes.perception.workspace``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ipr_shapes.perception.config import ContainersConfig, PerceptionConfig, SegmentationConfig
from ipr_shapes.perception.curvature import (
    join_curved_segments,
    signed_bends,
    smooth_concave_edges,
)
from ipr_shapes.perception.segmentation import segment_frame
from ipr_shapes.perception.types import Supervoxels
from ipr_shapes.scene import Frame
from tests.test_segmentation import box, camera, render, segment_of_point

STEP = 0.02  # supervoxel spacing (m), the seed size
CURVED = PerceptionConfig(
    segmentation=SegmentationConfig(
        curved_join_deg=40.0, curved_join_ratio=0.3, curved_segment_vote=0.3
    )
)
OFF = PerceptionConfig(
    segmentation=SegmentationConfig(curved_join_deg=0.0, curved_segment_vote=0.0)
)


def _grid(surface, columns: int = 9, rows: int = 4, colours=None) -> Supervoxels:
    """Supervoxels on a (rows x columns) grid, STEP apart along y and along the surface's arc
    length s across x, on the surface ``surface(s) -> (x, z, normal)`` (normals up, towards a
    camera above); 8-neighbour adjacency. ``colours``: (columns,) rgb per column."""
    centres, normals, colour = [], [], []
    for r in range(rows):
        for c in range(columns):
            x, z, normal = surface((c - (columns - 1) / 2) * STEP)
            centres.append([x, r * STEP, z])
            normals.append(normal)
            colour.append([0.5, 0.5, 0.5] if colours is None else colours[c])
    pairs = []
    for r in range(rows):
        for c in range(columns):
            for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
                if 0 <= r + dr < rows and 0 <= c + dc < columns:
                    pairs.append([r * columns + c, (r + dr) * columns + c + dc])
    count = rows * columns
    return Supervoxels(
        labels=np.zeros((1, count), np.int32),
        centres=np.array(centres, float),
        normals=np.array(normals, float),
        colours=np.array(colour, float),
        sizes=np.full(count, 100),
        adjacency=np.array(pairs, np.int64),
    )


def _valley(radius: float):
    """The bottom of a horizontal cylinder of ``radius`` (a bowl's inside in section)."""

    def surface(s: float):
        angle = s / radius
        normal = np.array([-np.sin(angle), 0.0, np.cos(angle)])
        return radius * np.sin(angle), radius * (1.0 - np.cos(angle)), normal

    return surface


def _crease(half_angle_deg: float):
    """Two flat faces meeting at x = 0 in a concave fold (two objects leaning together)."""
    t = np.radians(half_angle_deg)

    def surface(s: float):
        side = -1.0 if s < 0 else 1.0
        normal = np.array([-side * np.sin(t), 0.0, np.cos(t)])
        return s * np.cos(t), abs(s) * np.sin(t), normal

    return surface


def _along_x(supervoxels: Supervoxels) -> np.ndarray:
    pairs = supervoxels.adjacency
    offset = supervoxels.centres[pairs[:, 1]] - supervoxels.centres[pairs[:, 0]]
    return np.abs(offset[:, 1]) < 1e-9


def test_a_curved_concave_surface_bends_at_every_step_a_crease_once():
    bowl = _grid(_valley(0.08))  # 14.3 degrees per 2 cm step
    bends = signed_bends(bowl)[_along_x(bowl)]
    assert np.allclose(bends, np.degrees(STEP / 0.08), atol=0.5)  # concave: positive
    joined = smooth_concave_edges(bowl, CURVED)[_along_x(bowl)]
    # Every edge along the bend joins but those at the ends, where the surface stops.
    column = np.arange(bowl.count) % 9
    pairs = bowl.adjacency[_along_x(bowl)]
    ends = np.isin(column[pairs], (0, 8)).any(axis=1)
    assert joined[~ends].all() and not joined[ends].any()
    # A crease of about the same angle between two flat faces stays cut, and so does a bowl
    # when the join is off or the bend exceeds its limit.
    crease = _grid(_crease(8.0))  # a 16-degree fold at s = 0
    column = np.arange(crease.count) % 9
    at_crease = (np.sort(column[crease.adjacency], axis=1) == [3, 4]).all(axis=1)
    at_crease &= _along_x(crease)
    assert np.allclose(signed_bends(crease)[at_crease], 16.0, atol=0.1)  # about the bowl's
    assert np.allclose(signed_bends(crease)[_along_x(crease) & ~at_crease], 0.0, atol=0.1)
    assert not smooth_concave_edges(crease, CURVED).any()
    assert not smooth_concave_edges(bowl, OFF).any()
    narrow = replace(CURVED, segmentation=replace(CURVED.segmentation, curved_join_deg=12.0))
    assert not smooth_concave_edges(bowl, narrow).any()
    # Convex surfaces (a ball seen from above) are strong anyway, never "smooth concave".
    valley = _valley(0.08)
    ball = _grid(lambda s: (valley(s)[0], -valley(s)[1], valley(s)[2] * [-1, 1, 1]))
    assert (signed_bends(ball)[_along_x(ball)] < 0).all()
    assert not smooth_concave_edges(ball, CURVED).any()


def test_segments_meeting_along_a_curved_surface_are_joined_not_at_a_crease():
    halves = np.where(np.arange(36) % 9 < 4, 1, 2).astype(np.int32)  # columns 0-3 | 4-8
    bowl = join_curved_segments(halves, _grid(_valley(0.08)), CURVED)
    assert (bowl == 1).all()
    crease = join_curved_segments(halves, _grid(_crease(8.0)), CURVED)
    assert np.array_equal(crease, halves)
    # Not across a colour edge (a teal bowl against a red one), nor when switched off.
    colours = [[0.1, 0.5, 0.5]] * 4 + [[0.6, 0.1, 0.1]] * 5
    two_colours = join_curved_segments(halves, _grid(_valley(0.08), colours=colours), CURVED)
    assert np.array_equal(two_colours, halves)
    assert np.array_equal(join_curved_segments(halves, _grid(_valley(0.08)), OFF), halves)


# --------------------------------------------------------------------------------------------
# Workspace


def test_clutter_beyond_the_table_is_dropped_and_objects_on_it_kept():
    """The rendered table spans |x|, |y| < 0.5 m. Beyond its far edge stand a box (on a floor
    out of view) and a seat at the table's height with a box on it (a chair behind a table):
    neither box is an object of the workspace, while a box on the table and one overhanging
    its edge are."""
    pose = camera(1.1, 40.0, 0.0)  # looking along -x, the far edge at x = -0.5
    beyond = box(-0.62, 0.2, (0.08, 0.08, 0.10))
    seat = (np.array([-0.78, -0.15, 0.0]), np.array([0.12, 0.15, 0.002]), 0.0)
    on_seat = box(-0.78, -0.15, (0.08, 0.08, 0.08))
    on_table = box(0.0, 0.1, (0.08, 0.08, 0.10))
    at_edge = box(-0.49, -0.35, (0.08, 0.08, 0.08))
    frame = render(pose, boxes=[beyond, seat, on_seat, on_table, at_edge])
    plain = segment_frame(
        frame, config=PerceptionConfig(segmentation=SegmentationConfig(workspace_share=0.0))
    ).labels
    kept = segment_frame(frame).labels  # the default
    far, seated = (-0.62, 0.2, 0.1), (-0.78, -0.15, 0.08)
    table_point, edge_point = (0.0, 0.1, 0.1), (-0.49, -0.35, 0.08)
    assert segment_of_point(frame, plain, far) > 0  # segmented without the test
    assert segment_of_point(frame, plain, seated) > 0
    assert segment_of_point(frame, kept, far) == 0
    assert segment_of_point(frame, kept, seated) == 0
    assert segment_of_point(frame, kept, table_point) > 0
    assert segment_of_point(frame, kept, edge_point) > 0


# --------------------------------------------------------------------------------------------
# A rendered bowl under a real sensor's noise


def _noisy_bowl_frame(seed: int) -> tuple[Frame, np.ndarray]:
    """A teal hemispherical bowl (8 cm radius, open side up) on a table, seen from 0.75 m at
    50 degrees, and the bowl's pixels. Depth noise as a structured-light sensor's: standard
    deviation 2.5 mm x depth^2 (m), spatially correlated over a few pixels, and quantised in
    steps of 1.5 mm x depth^2 (the real frames' flat runs with steps)."""
    import trimesh
    from scipy import ndimage

    from ipr_shapes.camera import look_at
    from ipr_shapes.rendering import render_depth_and_ids
    from tests.box_scene import BACKDROP, TABLE
    from tests.test_segmentation import HEIGHT, WIDTH, K

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.08)
    lower = sphere.faces[sphere.triangles_center[:, 2] < 0.02]
    vertices = sphere.vertices + [0.0, 0.0, 0.08]
    faces = np.vstack([lower, lower[:, ::-1]])  # a thin shell: seen from both sides
    pose = look_at(np.array([0.0, -0.45, 0.6]), np.array([0.0, 0.0, 0.04]))
    meshes = [(vertices, faces), TABLE, BACKDROP]
    depth, index = render_depth_and_ids(meshes, [None] * 3, K, WIDTH, HEIGHT, pose)
    rng = np.random.default_rng(seed)
    correlated = ndimage.gaussian_filter(rng.normal(0.0, 1.0, depth.shape), 2.0)
    noisy = depth + 0.0025 * depth**2 * correlated / correlated.std()
    step = 0.0015 * np.maximum(depth, 0.1) ** 2
    noisy = np.where(depth > 0, np.round(noisy / step) * step, 0.0).astype(np.float32)
    colours = np.array([[40, 150, 150], [120, 120, 120], [90, 90, 90], [0, 0, 0]])
    return Frame(0, colours[index].astype(np.uint8), noisy, K, pose), index == 0


def _segments_on(labels: np.ndarray, pixels: np.ndarray, min_pixels: int = 40) -> int:
    counts = np.bincount(labels[pixels])
    return int((counts[1:] >= min_pixels).sum())


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_a_bowl_under_real_sensor_noise_stays_whole(seed):
    """LCCP alone cuts the bowl's inside into a dozen pieces (each 2 cm step bends it by
    about 14 degrees); with the curvature test it is at most its inside and its outer wall, and
    so it is with the containers' rim join alone (``tests/test_containers.py``)."""
    frame, bowl = _noisy_bowl_frame(seed)
    no_rims = ContainersConfig(join_rims=False)
    lccp = segment_frame(frame, config=replace(OFF, containers=no_rims)).labels
    curved = segment_frame(frame, config=PerceptionConfig(containers=no_rims)).labels
    assert _segments_on(lccp, bowl) >= 8
    assert _segments_on(curved, bowl) <= 2
    # The bowl's pixels are covered: joined, not dropped.
    assert (curved[bowl] > 0).mean() >= 0.9
    rims = segment_frame(frame, config=OFF).labels
    assert _segments_on(rims, bowl) <= 2
    assert (rims[bowl] > 0).mean() >= 0.9


def test_a_table_split_by_a_long_object_is_still_one_workspace():
    """A long low box runs across the whole table along the view, so the table's visible points
    fall into two regions; the box bridges them, and neither it nor a box on the smaller side
    is dropped."""
    pose = camera(1.1, 40.0, 0.0)
    long_box = (np.array([0.0, 0.15, 0.04]), np.array([0.6, 0.05, 0.04]), 0.0)
    small_side = box(-0.1, 0.35, (0.08, 0.08, 0.10))
    frame = render(pose, boxes=[long_box, small_side])
    kept = segment_frame(frame).labels  # the default
    assert segment_of_point(frame, kept, (-0.1, 0.35, 0.1)) > 0
    assert segment_of_point(frame, kept, (0.1, 0.15, 0.08)) > 0
