"""Concave edges on smoothly curved surfaces (``ipr_shapes.perception.curvature``) and the
workspace test (``ipr_shapes.perception.workspace``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ipr_shapes.perception.config import PerceptionConfig, SegmentationConfig
from ipr_shapes.perception.curvature import (
    join_curved_segments,
    signed_bends,
    smooth_concave_edges,
)
from ipr_shapes.perception.segmentation import segment_frame
from ipr_shapes.perception.types import Supervoxels
from tests.test_segmentation import box, camera, render, segment_of_point

STEP = 0.02  # supervoxel spacing (m), the seed size
CURVED = PerceptionConfig(
    segmentation=SegmentationConfig(
        curved_join_deg=40.0, curved_join_ratio=0.3, curved_segment_vote=0.3
    )
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
    assert not smooth_concave_edges(bowl, PerceptionConfig()).any()
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
    assert np.array_equal(
        join_curved_segments(halves, _grid(_valley(0.08)), PerceptionConfig()), halves
    )


# --------------------------------------------------------------------------------------------
# Workspace


def test_clutter_beyond_the_table_is_dropped_and_objects_on_it_kept():
    """The rendered table spans |x|, |y| < 0.5 m; a box standing beyond its edge (on a floor
    at the table's height out of view, as a chair's seat) is no object of the workspace, while a
    box on the table and one overhanging its edge are."""
    pose = camera(1.1, 40.0, 0.0)  # looking along -x, the far edge at x = -0.5
    beyond = box(-0.62, 0.0, (0.08, 0.08, 0.10))
    on_table = box(0.0, 0.1, (0.08, 0.08, 0.10))
    at_edge = box(-0.49, -0.25, (0.08, 0.08, 0.08))
    frame = render(pose, boxes=[beyond, on_table, at_edge])
    config = PerceptionConfig(segmentation=SegmentationConfig(workspace_share=0.5))
    plain = segment_frame(frame).labels
    kept = segment_frame(frame, config=config).labels
    far_point, table_point, edge_point = (-0.62, 0.0, 0.1), (0.0, 0.1, 0.1), (-0.49, -0.25, 0.08)
    assert segment_of_point(frame, plain, far_point) > 0  # segmented without the test
    assert segment_of_point(frame, kept, far_point) == 0
    assert segment_of_point(frame, kept, table_point) > 0
    assert segment_of_point(frame, kept, edge_point) > 0
