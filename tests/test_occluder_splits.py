"""One segment for an object cut in two by a nearer object (ipr_shapes.perception.occluder_splits)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.occluder_splits import join_occluder_splits, quadric_rms
from ipr_shapes.perception.segmentation import segment_frame
from ipr_shapes.perception.tracking import track_segments
from tests.test_segmentation import box, camera, render, segment_of_point

DEFAULT = PerceptionConfig()
ON = replace(DEFAULT, occluder_splits=replace(DEFAULT.occluder_splits, enabled=True))
#: A long low box on the table and a thin tall bar standing in front of its middle (the camera
#: looks from -y, above): the bar hides a band across the box, cutting it in two in the image.
LONG_BOX = box(0.0, 0.0, (0.24, 0.08, 0.05))
BAR = box(0.05, -0.12, (0.015, 0.04, 0.20))
LEFT, RIGHT, ON_BAR = (-0.09, 0.0, 0.05), (0.09, 0.0, 0.05), (0.05, -0.12, 0.2)


def _labels_at(frame, labels, *points) -> list[int]:
    return [segment_of_point(frame, labels, p) for p in points]


def test_quadric_residual_is_zero_on_a_curved_patch_and_not_across_a_step():
    x, y = np.meshgrid(np.linspace(-0.1, 0.1, 30), np.linspace(-0.05, 0.05, 20))
    cap = np.stack([x, y, 0.5 * (x**2 + y**2)], axis=-1).reshape(-1, 3)
    assert quadric_rms(cap) < 1e-9
    step = np.stack([x, y, np.where(x > 0, 0.03, 0.0)], axis=-1).reshape(-1, 3)
    assert quadric_rms(step) > 0.005


def test_a_box_cut_in_two_by_a_nearer_bar_is_one_segment_with_the_switch():
    frame = render(camera(), boxes=[LONG_BOX, BAR])
    left, right, bar = _labels_at(frame, segment_frame(frame).labels, LEFT, RIGHT, ON_BAR)
    assert len({left, right, bar}) == 3 and 0 not in (left, right, bar)  # the split it undoes
    left, right, bar = _labels_at(
        frame, segment_frame(frame, config=ON).labels, LEFT, RIGHT, ON_BAR
    )
    assert left == right != bar and left > 0 and bar > 0


#: Synthetic frames for the join alone: a camera looking straight down (camera = world frame),
#: 2 mm per pixel at 1 m; the table 1.1 m away, unlabelled.
FOCAL_PX = 500.0


def _frame(pieces, bar_rows=(10, 70), bar_cols=(56, 66)):
    """(labels, points, depth, rgb) of a flat piece pair under a bar: ``pieces`` lists (label,
    columns, depth m, rgb) of the pieces (rows 20-59); the bar (label 3, depth 0.9 m) covers
    ``bar_rows`` x ``bar_cols`` between the pieces."""
    height, width = 80, 120
    labels = np.zeros((height, width), np.int32)
    depth = np.full((height, width), 1.1)
    rgb = np.full((height, width, 3), 90, np.uint8)
    for label, (first, last), piece_depth, colour in pieces:
        labels[20:60, first:last] = label
        depth[20:60, first:last] = piece_depth
        rgb[20:60, first:last] = colour
    bar = slice(*bar_rows), slice(*bar_cols)
    labels[bar], depth[bar], rgb[bar] = 3, 0.9, (30, 30, 200)
    return labels, _points(depth), depth, rgb


def _points(depth):
    """(H, W, 3) points (m) of an (H, W) depth image (m) seen by the downward camera."""
    height, width = depth.shape
    rows, cols = np.mgrid[0:height, 0:width]
    return np.stack(
        [(cols - width / 2) / FOCAL_PX * depth, (rows - height / 2) / FOCAL_PX * depth, depth],
        axis=-1,
    )


GREY = (150, 140, 130)
ONE_BOX = [(1, (20, 56), 1.0, GREY), (2, (66, 100), 1.0, GREY)]


def _join(labels, points, depth, rgb, config=ON.occluder_splits):
    segments = np.arange(4, dtype=np.int32)  # supervoxel k in segment k
    return join_occluder_splits(labels, segments, points, depth, rgb, config)


def test_one_surface_on_both_sides_of_a_bar_is_joined_and_its_supervoxels_too():
    labels, segments, joins = _join(*_frame(ONE_BOX))
    assert joins == [(1, 2)]
    assert set(np.unique(labels).tolist()) == {0, 1, 3}
    assert segments.tolist() == [0, 1, 1, 3]
    assert _join(*_frame(ONE_BOX), config=DEFAULT.occluder_splits)[2] == []


@pytest.mark.parametrize(
    ("pieces", "bar_rows", "bar_cols"),
    [
        # The bar hides only the upper half of the gap: the table is seen between the pieces.
        (ONE_BOX, (10, 40), (56, 66)),
        # The right piece 3 cm nearer: two surfaces meeting in a step, not one running on.
        ([(1, (20, 56), 1.0, GREY), (2, (66, 100), 0.97, GREY)], (10, 70), (56, 66)),
        # The right piece red.
        ([(1, (20, 56), 1.0, GREY), (2, (66, 100), 1.0, (200, 30, 30))], (10, 70), (56, 66)),
        # 8 cm apart (40 px at 2 mm) behind a bar as wide: too long a hidden part.
        ([(1, (20, 40), 1.0, GREY), (2, (80, 100), 1.0, GREY)], (10, 70), (40, 80)),
    ],
    ids=["table seen between", "a step between", "another colour", "too far apart"],
)
def test_pieces_that_are_not_one_object_stay_apart(pieces, bar_rows, bar_cols):
    assert _join(*_frame(pieces, bar_rows, bar_cols))[2] == []


def test_two_rendered_boxes_with_the_table_between_them_stay_apart():
    two = [box(-0.07, 0.0, (0.10, 0.08, 0.05)), box(0.07, 0.0, (0.10, 0.08, 0.05)), BAR]
    frame = render(camera(), boxes=two)
    left, right = _labels_at(frame, segment_frame(frame, config=ON).labels, LEFT, RIGHT)
    assert left != right and left > 0 and right > 0


def test_the_tracker_keeps_one_id_when_the_bar_is_taken_away():
    """Frame 0: the bar cuts the box in two; frame 1: the bar is gone, the box whole. With the
    join the whole box keeps the id both its pieces had; without it one piece's id is lost."""
    frames = [render(camera(), boxes=[LONG_BOX, BAR]), render(camera(), boxes=[LONG_BOX])]
    for config, kept in ((ON, True), (DEFAULT, False)):
        labels = [segment_frame(f, config=config).labels for f in frames]
        tracked = track_segments(
            labels,
            [f.points_world() for f in frames],
            [f.rgb for f in frames],
            config.tracking,
            frames_depth=[f.depth_m for f in frames],
        )
        first = _labels_at(frames[0], tracked[0], LEFT, RIGHT)
        later = _labels_at(frames[1], tracked[1], LEFT, RIGHT)
        assert later[0] == later[1]
        assert (first == later) is kept


def test_pieces_with_mostly_seen_surface_between_them_stay_apart():
    """The bar borders both pieces along an arm across the top of the gap (rows 20-21), but
    below the arm, on each side of the bar, another segment lies at the pieces' own depth: most
    of the gap is seen, not hidden (the occluded share well below ``min_occluded``), so
    nothing says one surface runs on under the bar. With the whole gap under the bar the same
    pieces are joined."""
    pieces = [(1, (20, 48), 1.0, GREY), (2, (74, 100), 1.0, GREY)]
    assert _join(*_frame(pieces, (10, 70), (48, 74)))[2] == [(1, 2)]
    strips = [(4, (48, 59), 1.0, (40, 90, 40)), (4, (63, 74), 1.0, (40, 90, 40))]
    labels, _, depth, rgb = _frame(pieces + strips, (10, 70), (59, 63))
    labels[20:22, 48:74], depth[20:22, 48:74], rgb[20:22, 48:74] = 3, 0.9, (30, 30, 200)
    assert _join(labels, _points(depth), depth, rgb)[2] == []
