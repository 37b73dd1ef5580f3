"""Cutting segments along straight colour seams (``ipr_shapes.perception.seams``, opt-in).

Two boxes of one height touching side by side have coplanar tops: the convexity graph sees one
surface. Painted like real packed boxes (a thin dark gap between them, or boxes of different
colours), the seam setting cuts a row of three at both seams and a grid of 3 x 2 at every
seam, and a pair apart when a lone midway seam is allowed (``pair_needs_grid`` False); it
leaves alone a box's own edge (a crease), a stripe that ends inside a face, a printed end
panel (its strips are not one box size), a line through one box's middle (a pair by default),
a straight line on a ball (a curve in 3D), and everything when it is off. A printed line
across a whole row, cut and undone, does not undo the seams between the row's boxes.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ipr_shapes.perception.config import PerceptionConfig, SeamsConfig
from ipr_shapes.perception.seams import (
    Normals,
    _area_m2,
    _covered,
    _cut_by_planes,
    _dilate_square,
    _equally_spaced,
    _FacesElsewhere,
    _FrameFaces,
    _has_area,
    _is_shadow,
    _linked_edges,
    _row_percentiles,
    _Seam,
    _sized_like,
    _Sizes,
    _thin,
    _undo,
    _unrepeated,
    cut_colour_seams,
)
from ipr_shapes.perception.segmentation import _cut_seams, segment_frame
from ipr_shapes.scene import Frame
from tests.test_segmentation import box, camera, render, segment_of_point

ON = replace(PerceptionConfig(), seams=SeamsConfig(enabled=True))
#: Seams on, a lone seam midway across a segment kept too (two boxes side by side).
PAIRS = replace(ON, seams=replace(ON.seams, pair_needs_grid=False))
#: Seams on without the shadow lines: a painted dark gap is then a line like any printed one
#: (the tests of the strip tests' own rules).
NO_SHADOWS = replace(ON, seams=replace(ON.seams, shadow_lines=False))
TOP = 0.06  # the boxes' height (m)


def painted(frame: Frame, dark, ink=(40, 40, 40)) -> Frame:
    """``frame`` with a light, slightly noisy image and the pixels whose world point satisfies
    ``dark(points)`` (an (N, 3) -> (N,) bool) painted dark (``ink``, RGB; by default grey: a
    shadow, less light in every channel alike)."""
    points = frame.points_world().reshape(-1, 3)
    rng = np.random.default_rng(1)
    rgb = (200 + rng.integers(-3, 4, (points.shape[0], 3))).astype(np.uint8)
    rgb[(frame.depth_m.reshape(-1) > 0) & dark(points)] = ink
    return Frame(frame.index, rgb.reshape(*frame.depth_m.shape, 3), frame.depth_m, frame.K,
                 frame.world_from_camera)  # fmt: skip


def two_boxes(dark) -> Frame:
    """Two 10 cm boxes, 6 cm high, touching along y = 0."""
    boxes = [box(0.0, -0.05, (0.1, 0.1, TOP)), box(0.0, 0.05, (0.1, 0.1, TOP))]
    return painted(render(camera(), boxes, noise_m=0.0005), dark)


def gap_between(points: np.ndarray) -> np.ndarray:
    """The thin gap between the two tops (4 mm wide, along y = 0)."""
    return (np.abs(points[:, 1]) < 0.002) & (points[:, 2] > TOP - 0.004)


def centres(labels: np.ndarray, frame: Frame) -> tuple[int, int]:
    return (
        segment_of_point(frame, labels, [0.0, -0.05, TOP]),
        segment_of_point(frame, labels, [0.0, 0.05, TOP]),
    )


def test_touching_boxes_of_one_height_merge_without_seams():
    frame = two_boxes(gap_between)
    a, b = centres(segment_frame(frame).labels, frame)
    assert a > 0 and a == b


def test_a_seam_between_coplanar_tops_cuts_the_boxes_apart():
    frame = two_boxes(gap_between)
    result = segment_frame(frame, config=PAIRS)
    a, b = centres(result.labels, frame)
    assert a > 0 and b > 0 and a != b
    # Each box is one piece: its top's corners are in its own segment.
    assert segment_of_point(frame, result.labels, [0.04, -0.09, TOP]) == a
    assert segment_of_point(frame, result.labels, [-0.04, 0.09, TOP]) == b
    # Labels are 1..k by decreasing size, and every supervoxel's segment is one of them.
    ids = np.unique(result.labels[result.labels > 0])
    assert ids.tolist() == list(range(1, len(ids) + 1))
    sizes = [int((result.labels == i).sum()) for i in ids]
    assert sizes == sorted(sizes, reverse=True)
    assert set(np.unique(result.segment_of_supervoxel)) <= set(ids.tolist()) | {0}


def test_a_colour_edge_along_a_crease_is_the_objects_own():
    # One box whose top is light and sides dark: the colour edge runs along its convex edges.
    frame = painted(
        render(camera(), [box(0.0, 0.0, (0.1, 0.2, TOP))], noise_m=0.0005),
        lambda points: points[:, 2] < TOP - 0.003,
    )
    labels = segment_frame(frame, config=ON).labels
    assert segment_of_point(frame, labels, [0.0, -0.08, TOP]) == segment_of_point(
        frame, labels, [0.0, 0.08, TOP]
    )
    assert len(np.unique(labels[labels > 0])) == 1


def test_a_stripe_that_ends_inside_the_face_does_not_cut():
    # The gap painted only half way across: a line that does not reach the outline.
    frame = two_boxes(lambda points: gap_between(points) & (points[:, 0] > 0.0))
    a, b = centres(segment_frame(frame, config=ON).labels, frame)
    assert a > 0 and a == b


def test_a_lone_seam_midway_is_kept_only_in_a_grid():
    # One seam midway across a segment is two boxes or one box with a printed line through its
    # middle: by default it stays whole (the line on one box is the likelier on a tabletop).
    frame = two_boxes(gap_between)
    a, b = centres(segment_frame(frame, config=NO_SHADOWS).labels, frame)
    assert a > 0 and a == b


def pair_beside_a_row(ink=(40, 40, 40)) -> tuple[Frame, list, list]:
    """A pair of 10 x 7 cm boxes touching along y = 0 (x < 0) beside a row of three 10 cm
    boxes (x = 0.12), every gap painted ``ink``; the pair's two top centres, the row's three."""
    pair = [box(-0.1, y, (0.1, 0.07, TOP)) for y in (-0.035, 0.035)]
    row = [box(0.12, y, (0.1, 0.1, TOP)) for y in (-0.1, 0.0, 0.1)]

    def gaps(points):
        return (gap_between(points) & (points[:, 0] < 0.0)) | (
            row_gaps(points) & (points[:, 0] > 0.0)
        )

    frame = painted(render(camera(), pair + row, noise_m=0.0005), gaps, ink=ink)
    return frame, [[-0.1, y, TOP] for y in (-0.05, 0.05)], [[0.12, y, TOP] for y in (-0.1, 0, 0.1)]


def test_a_lone_shadow_line_midway_is_a_gap_where_packed_boxes_are_seen():
    # The pair's gap is a shadow (grey: every channel darker alike) and its halves match no
    # box in the frame; the row beside it is cut by the strip tests (boxes of one size), so
    # the frame holds packed boxes: the pair is cut too. Without the shadow lines it is not.
    frame, pair, row = pair_beside_a_row()
    for config, cut in ((ON, True), (NO_SHADOWS, False)):
        labels = segment_frame(frame, config=config).labels
        assert len({segment_of_point(frame, labels, point) for point in row}) == 3
        a, b = (segment_of_point(frame, labels, point) for point in pair)
        assert a > 0 and b > 0 and (a != b) is cut


def test_a_lone_shadow_line_is_not_cut_where_no_packed_boxes_are_seen():
    # The pair alone: a grey line through one box's middle (black ink) looks the same, and no
    # cut kept elsewhere in the frame says that it holds packed boxes.
    frame = two_boxes(gap_between)
    a, b = centres(segment_frame(frame, config=ON).labels, frame)
    assert a > 0 and a == b


def _line_across(side_a, side_b, line) -> tuple[_Seam, np.ndarray]:
    """A vertical seam down column 20 of a 40 x 41 crop: colour ``side_a`` left of it,
    ``side_b`` right of it, ``line`` on it (2 px wide), each (R, G, B)."""
    rgb = np.empty((40, 41, 3), dtype=np.uint8)
    rgb[:, :20] = side_a
    rgb[:, 21:] = side_b
    rgb[:, 19:22] = line
    rows = np.arange(40)
    return _seam_at_column(20, rows), rgb


@pytest.mark.parametrize(
    "side_a, side_b, line, shadow",
    [
        ((200, 200, 200), (200, 200, 200), (120, 120, 120), True),  # a gap's shadow
        ((180, 40, 40), (176, 42, 38), (108, 24, 24), True),  # on red boxes: 0.6 of each
        ((200, 200, 200), (120, 120, 120), (100, 100, 100), False),  # a step: a border
        ((200, 200, 200), (200, 200, 200), (200, 40, 40), False),  # red ink: red not darker
        ((200, 200, 200), (200, 200, 200), (180, 60, 60), False),  # channels darken unalike
        ((200, 200, 200), (200, 200, 200), (200, 200, 200), False),  # no line
    ],
)
def test_a_shadow_line_is_darker_than_both_sides_in_every_channel_alike(
    side_a, side_b, line, shadow
):
    seam, rgb = _line_across(side_a, side_b, line)
    assert _is_shadow(seam, rgb) is shadow


def test_a_coloured_printed_line_midway_is_not_a_shadow():
    # Red lines (ink absorbing green and blue only) where the gaps were: the pair's is a
    # printed line through one box's middle as far as one view tells, even beside the row.
    frame, pair, row = pair_beside_a_row(ink=(190, 40, 40))
    labels = segment_frame(frame, config=ON).labels
    assert len({segment_of_point(frame, labels, point) for point in row}) == 3
    a, b = (segment_of_point(frame, labels, point) for point in pair)
    assert a > 0 and a == b


def test_a_lone_seam_is_kept_when_a_box_of_its_strips_size_is_seen_elsewhere():
    # The pair beside a third, separate box of the same size: packed boxes repeat across the
    # frame, so the pair is two boxes. A box of another size (6 x 14 cm) does not tell.
    def scene(size):
        boxes = [box(0.0, -0.05, (0.1, 0.1, TOP)), box(0.0, 0.05, (0.1, 0.1, TOP))]
        boxes.append(box(-0.2, 0.0, (*size, TOP)))
        return painted(render(camera(), boxes, noise_m=0.0005), gap_between)

    frame = scene((0.1, 0.1))
    result = segment_frame(frame, config=NO_SHADOWS)
    a, b = centres(result.labels, frame)
    assert a > 0 and b > 0 and a != b
    assert segment_of_point(frame, result.labels, [-0.2, 0.0, TOP]) not in (0, a, b)
    frame = scene((0.06, 0.14))
    a, b = centres(segment_frame(frame, config=NO_SHADOWS).labels, frame)
    assert a > 0 and a == b
    # And only with the sizes' test on.
    no_sizes = replace(NO_SHADOWS, seams=replace(NO_SHADOWS.seams, pair_sizes=False))
    frame = scene((0.1, 0.1))
    a, b = centres(segment_frame(frame, config=no_sizes).labels, frame)
    assert a > 0 and a == b


def test_two_pairs_of_one_size_are_four_boxes():
    # Two separate pairs of 10 cm boxes, each one segment with one seam midway: each pair's
    # halves have the size of the other pair's, so both are cut.
    boxes = [box(x, y, (0.1, 0.1, TOP)) for x in (0.0, 0.2) for y in (-0.05, 0.05)]
    frame = painted(render(camera(), boxes, noise_m=0.0005), gap_between)

    def boxes_seen(config):
        labels = segment_frame(frame, config=config).labels
        ids = [
            segment_of_point(frame, labels, [x, y, TOP]) for x in (0.0, 0.2) for y in (-0.05, 0.05)
        ]
        assert min(ids) > 0
        return len(set(ids))

    assert boxes_seen(NO_SHADOWS) == 4
    assert boxes_seen(replace(NO_SHADOWS, seams=replace(NO_SHADOWS.seams, pair_sizes=False))) == 2


def test_a_short_seam_is_not_a_seam():
    # Cutting needs min_length_m of seam: 10 cm boxes are too short for 15 cm.
    config = replace(PAIRS, seams=replace(PAIRS.seams, min_length_m=0.15))
    frame = two_boxes(gap_between)
    a, b = centres(segment_frame(frame, config=config).labels, frame)
    assert a > 0 and a == b


@pytest.mark.parametrize(
    "field, value",
    [
        ("coverage", 1.5),
        ("edge_factor", 0.0),
        ("max_cuts", -1),
        ("max_normal_deg", 200.0),
        ("max_bend_m", -0.001),
        ("strip_tolerance", 1.5),
    ],
)
def test_seam_settings_are_checked(field, value):
    with pytest.raises(ValueError, match=field):
        SeamsConfig(**{field: value})


def three_boxes(dark) -> Frame:
    """Three 10 cm boxes, 6 cm high, in a row along y, touching at y = -0.05 and y = 0.05."""
    boxes = [box(0.0, y, (0.1, 0.1, TOP)) for y in (-0.1, 0.0, 0.1)]
    return painted(render(camera(), boxes, noise_m=0.0005), dark)


def test_touching_boxes_of_different_colours_are_cut_apart():
    # No gap line: the seam is the step from a dark box to a light one.
    frame = two_boxes(lambda points: points[:, 1] < 0.0)
    a, b = centres(segment_frame(frame, config=PAIRS).labels, frame)
    assert a > 0 and b > 0 and a != b


def test_a_row_of_boxes_of_one_size_is_cut_at_every_seam():
    frame = three_boxes(row_gaps)
    labels = segment_frame(frame, config=ON).labels
    ids = [segment_of_point(frame, labels, [0.0, y, TOP]) for y in (-0.1, 0.0, 0.1)]
    assert min(ids) > 0 and len(set(ids)) == 3


def row_gaps(points: np.ndarray) -> np.ndarray:
    """The thin gaps between the tops of ``three_boxes`` (4 mm wide, at y = +-0.05)."""
    return (np.abs(np.abs(points[:, 1]) - 0.05) < 0.002) & (points[:, 2] > TOP - 0.004)


@pytest.mark.slow
def test_a_grid_of_boxes_is_cut_at_every_seam():
    # 3 x 2 boxes of 10 cm: the seams along x lie between seams (a row of three), the seam
    # along y midway between the outlines, and it meets them (a grid).
    boxes = [box(x, y, (0.1, 0.1, TOP)) for x in (-0.05, 0.05) for y in (-0.1, 0.0, 0.1)]
    frame = painted(
        render(camera(), boxes, noise_m=0.0005),
        lambda points: (
            (row_gaps(points) | (np.abs(points[:, 0]) < 0.002)) & (points[:, 2] > TOP - 0.004)
        ),
    )
    labels = segment_frame(frame, config=ON).labels
    ids = [
        segment_of_point(frame, labels, [x, y, TOP])
        for x in (-0.05, 0.05)
        for y in (-0.1, 0.0, 0.1)
    ]
    assert min(ids) > 0 and len(set(ids)) == 6


def test_an_undone_line_across_a_row_keeps_the_rows_seams():
    # A printed line across a row of three boxes, cut first (the longest seam), then the gaps
    # between the boxes below it: undoing the line (its strips are no box size) joins the strip
    # above it to one box it faces, not the three boxes to each other through the strip.
    pieces = np.zeros((30, 30), dtype=np.int32)
    pieces[:10] = 1
    pieces[10:, :10], pieces[10:, 10:19], pieces[10:, 19:] = 2, 3, 4
    cols = np.arange(30)
    line = _Seam(
        rows=np.full(30, 10), cols=cols, cos_a=0.0, sin_a=1.0, middle=np.zeros(3),
        direction=np.array([1.0, 0.0, 0.0]), across=np.array([0.0, 1.0, 0.0]),
        normal=np.array([0.0, 0.0, 1.0]), half_length_m=0.15,
    )  # fmt: skip
    joined = _undo(pieces, line)
    assert len(np.unique(joined)) == 3
    assert joined[0, 0] == joined[20, 25]  # the strip joins the box it faces along most
    assert len({joined[20, 5], joined[20, 15], joined[20, 25]}) == 3


def _grid_points(shape: tuple[int, int]) -> np.ndarray:
    """(h, w, 3) world points of a flat top, pixel (r, c) at (c, r, 0) cm."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    return np.stack([cols * 0.01, rows * 0.01, np.zeros(shape)], axis=2)


def _row_below_a_line(pieces: np.ndarray, cuts: list[int]) -> tuple[_Seam, list[_Seam]]:
    """The printed line along row 10 (to be undone) and the kept seams between the boxes below
    it, at the columns ``cuts`` (each between column c - 1 and c), on ``_grid_points``."""
    cols = np.arange(pieces.shape[1])
    line = _Seam(
        rows=np.full(len(cols), 10), cols=cols, cos_a=0.0, sin_a=1.0,
        middle=np.array([0.15, 0.1, 0.0]), direction=np.array([1.0, 0.0, 0.0]),
        across=np.array([0.0, 1.0, 0.0]), normal=np.array([0.0, 0.0, 1.0]), half_length_m=0.15,
    )  # fmt: skip
    rows = np.arange(11, pieces.shape[0])
    kept = [
        _Seam(
            rows=rows,
            cols=np.full(len(rows), cut),
            cos_a=1.0,
            sin_a=0.0,
            middle=np.array([0.01 * cut - 0.005, 0.2, 0.0]),
            direction=np.array([0.0, 1.0, 0.0]),
            across=np.array([1.0, 0.0, 0.0]),
            normal=np.array([0.0, 0.0, 1.0]),
            half_length_m=0.1,
        )  # fmt: skip
        for cut in cuts
    ]
    return line, kept


def test_an_undone_line_across_a_row_is_cut_along_the_rows_seams():
    # The row's boxes go on beyond a printed line across them (their barcode ends, their end
    # faces): undoing the line cuts the strip beyond it along the planes of the seams kept
    # between the boxes, and each part joins its own box.
    pieces = np.zeros((30, 30), dtype=np.int32)
    pieces[:10] = 1
    pieces[10:, :10], pieces[10:, 10:19], pieces[10:, 19:] = 2, 3, 4
    line, kept = _row_below_a_line(pieces, [10, 19])
    points = _grid_points(pieces.shape)
    measured = np.ones(pieces.shape, dtype=bool)
    measured[0, :] = False  # pixels without depth go with their neighbours
    joined = _undo(pieces, line, kept, points, measured, ON)
    assert len(np.unique(joined[joined > 0])) == 3
    for col in (0, 5, 15, 25, 29):
        assert joined[0, col] == joined[5, col] == joined[25, col]
    assert len({joined[20, 5], joined[20, 15], joined[20, 25]}) == 3
    # Without the kept seams' planes: the strip joins one box only (as before).
    alone = _undo(pieces, line)
    assert alone[5, 5] != alone[20, 5] or alone[5, 25] != alone[20, 25]


def test_a_wider_piece_beyond_an_undone_line_is_not_cut_along_the_rows_seams():
    # Another box lying across the row's end (wider than the row's boxes it faces): it does
    # not end at their seams, so it is not cut; it joins the one box it faces most, as before.
    pieces = np.zeros((30, 30), dtype=np.int32)
    pieces[:10] = 1
    pieces[10:, :10], pieces[10:, 10:19] = 2, 3
    line, kept = _row_below_a_line(pieces, [10])
    measured = np.ones(pieces.shape, dtype=bool)
    joined = _undo(pieces, line, kept, _grid_points(pieces.shape), measured, ON)
    assert len(np.unique(joined[:10])) == 1
    assert joined[20, 5] != joined[20, 15]


def _seam_at_column(col: int, rows: np.ndarray) -> _Seam:
    """A seam along column ``col`` (between col - 1 and col) of ``_grid_points``' top."""
    return _Seam(
        rows=rows, cols=np.full(len(rows), col), cos_a=1.0, sin_a=0.0,
        middle=np.array([0.01 * col - 0.005, 0.01 * float(rows.mean()), 0.0]),
        direction=np.array([0.0, 1.0, 0.0]), across=np.array([1.0, 0.0, 0.0]),
        normal=np.array([0.0, 0.0, 1.0]), half_length_m=0.005 * len(rows),
    )  # fmt: skip


def test_a_row_beyond_a_kept_seam_is_cut_along_the_seams_of_the_row_it_faces():
    # A grid of two rows: the seam between the rows is kept, the seams between the far row's
    # boxes were found but the near row's (bending over its front faces) were not. The near
    # row is cut along the far row's seams' planes, each part a box of its own.
    pieces = np.zeros((30, 30), dtype=np.int32)
    pieces[:10] = 1
    pieces[10:, :10], pieces[10:, 10:20], pieces[10:, 20:] = 2, 3, 4
    between_rows, _ = _row_below_a_line(pieces, [])
    far = [_seam_at_column(col, np.arange(11, 30)) for col in (10, 20)]
    points = _grid_points(pieces.shape)
    measured = np.ones(pieces.shape, dtype=bool)
    cut = _cut_by_planes(pieces, between_rows, far, points, measured, ON)
    near = {cut[5, 5], cut[5, 15], cut[5, 25]}
    assert len(near) == 3 and not near & {2, 3, 4}
    assert np.array_equal(cut[10:], pieces[10:])
    # Rows laid like bricks: the near row's own seam lies between the far row's seams (5 cm
    # off the one at column 20), so their planes are not its boxes' boundaries.
    pieces[:10, 25:] = 5
    own = _seam_at_column(25, np.arange(0, 10))
    offset = _cut_by_planes(pieces, between_rows, [*far, own], points, measured, ON)
    assert np.array_equal(offset, pieces)


def test_a_printed_border_across_one_box_is_not_a_seam():
    # One 20 cm box whose last quarter is printed dark: the border crosses the top from
    # outline to outline like a seam, but it leaves strips of 15 and 5 cm, not one box size.
    frame = painted(
        render(camera(), [box(0.0, 0.0, (0.1, 0.2, TOP))], noise_m=0.0005),
        lambda points: points[:, 1] > 0.05,
    )
    labels = segment_frame(frame, config=ON).labels
    assert segment_of_point(frame, labels, [0.0, -0.06, TOP]) == segment_of_point(
        frame, labels, [0.0, 0.08, TOP]
    )
    # Without the strip test the border is cut (the test above can fail).
    loose = replace(ON, seams=replace(ON.seams, strip_tolerance=1.0))
    labels = segment_frame(frame, config=loose).labels
    assert segment_of_point(frame, labels, [0.0, -0.06, TOP]) != segment_of_point(
        frame, labels, [0.0, 0.08, TOP]
    )


@pytest.mark.slow
def test_a_straight_line_on_a_ball_is_not_a_seam():
    # A 30 cm ball with a dark band in a plane through the camera: a straight line in the
    # image through the ball's middle, splitting it in two halves, but a curve in 3D, and
    # the halves are not flat.
    radius = 0.15
    world_from_camera = camera(distance=0.9)
    eye = world_from_camera[:3, 3]
    centre = np.array([0.0, 0.0, radius])
    sight = centre - eye
    band_normal = np.cross(sight, [0.0, 0.0, 1.0])
    band_normal /= np.linalg.norm(band_normal)
    frame = painted(
        render(world_from_camera, spheres=[(centre, radius)], noise_m=0.0005),
        lambda points: np.abs((points - eye) @ band_normal) < 0.003,
    )
    left = centre + 0.08 * band_normal
    right = centre - 0.08 * band_normal
    labels = segment_frame(frame, config=ON).labels
    assert segment_of_point(frame, labels, left) == segment_of_point(frame, labels, right)
    # The bend test alone keeps it whole (strip_tolerance = 1: no strip tests after the cuts),
    # and without it the band is cut (the tests above can fail).
    no_strips = replace(ON, seams=replace(ON.seams, strip_tolerance=1.0))
    labels = segment_frame(frame, config=no_strips).labels
    assert segment_of_point(frame, labels, left) == segment_of_point(frame, labels, right)
    loose = replace(no_strips, seams=replace(no_strips.seams, max_bend_m=1.0))
    labels = segment_frame(frame, config=loose).labels
    assert segment_of_point(frame, labels, left) != segment_of_point(frame, labels, right)


def flat_seam(y: float) -> _Seam:
    """A 20 cm seam along x at ``y`` (m) on the plane z = 0 (one pixel: ``_unrepeated`` reads
    the 3D line only)."""
    return _Seam(
        rows=np.zeros(1, dtype=np.int64), cols=np.zeros(1, dtype=np.int64), cos_a=0.0,
        sin_a=1.0, middle=np.array([0.0, y, 0.0]), direction=np.array([1.0, 0.0, 0.0]),
        across=np.array([0.0, 1.0, 0.0]), normal=np.array([0.0, 0.0, 1.0]), half_length_m=0.1,
    )  # fmt: skip


def kept_seams(offsets: tuple[float, ...], config: PerceptionConfig) -> list[float]:
    """The offsets (m) of the seams ``_unrepeated`` keeps, of seams at ``offsets`` across a
    flat segment from y = -0.2 to 0.24 m: a row of four boxes whose last strip measures 14 cm
    to the outline (a side face seen, a leaning box), the others 10 cm."""
    xs, ys = np.meshgrid(np.linspace(-0.1, 0.1, 41), np.linspace(-0.2, 0.24, 89))
    cloud = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    found = [flat_seam(y) for y in offsets]
    dropped = _unrepeated(found, cloud, [True] * len(found), config)
    return [
        y for y, seam in zip(offsets, found, strict=True) if all(seam is not d for d in dropped)
    ]


def test_three_seams_at_one_spacing_are_kept_whatever_the_row_ends_measure():
    # The end seam's strips (10 and 14 cm to the outline) do not agree; it lies at one spacing
    # with the two seams beside it, a row of boxes of one size. Without that rule the end seam
    # drops and the others after it (a dropped seam is no bound): the whole row merges.
    assert kept_seams((-0.1, 0.0, 0.1), ON) == [-0.1, 0.0, 0.1]
    off = replace(ON, seams=replace(ON.seams, rows_of_three=False))
    assert kept_seams((-0.1, 0.0, 0.1), off) == []
    # Seams at no one spacing (10 and 14 cm apart) are not a row of one size.
    assert kept_seams((-0.1, 0.0, 0.14), ON) == []
    assert _equally_spaced(np.array([0.1, 0.19]), ON)  # 10 and 9 cm
    assert not _equally_spaced(np.array([0.1, 0.24]), ON)  # 10 and 14 cm
    assert not _equally_spaced(np.array([0.1, 0.11]), ON)  # 1 cm: no box


def test_faint_stretches_of_a_strong_edge_are_linked_and_lone_faint_lines_are_not():
    # A horizontal line of gradient 5 (strong above 4) for 30 px fading to 3 (weak above 2)
    # for the next 30 px, and a separate line of 3 elsewhere: hysteresis keeps the fade only.
    magnitude = np.full((40, 100), 0.5, dtype=np.float32)
    magnitude[10, 10:40], magnitude[10, 40:70] = 5.0, 3.0
    magnitude[30, 10:70] = 3.0
    gx, gy = np.zeros_like(magnitude), np.ones_like(magnitude)  # gradients across the lines
    direction = np.zeros_like(magnitude)
    strong = np.flatnonzero(magnitude > 4.0)
    direction.flat[strong] = np.pi / 2
    edges = _thin(magnitude, direction, strong)
    near = np.ones(magnitude.shape, dtype=bool)
    linked = _linked_edges(magnitude, gx, gy, direction, edges, 2.0, near)
    assert linked[10, 10:70].all()
    assert not linked[30].any()
    assert not linked[:, 70:].any() and not linked[:9].any()


def faded_seam(strong_end: float) -> tuple:
    """``cut_colour_seams`` inputs: a flat 10 x 20 cm face (1 mm pixels at 1 m, light grey with
    +-2 levels of noise) with a 2 px dark line across its middle, ``strong_end`` levels darker
    at its left end and fading to 4 levels darker (about 3.6 times the frame's median colour
    gradient: above half the edge threshold, below it) from a third of the way along."""
    height, width = 124, 224
    rng = np.random.default_rng(0)
    rgb = 200.0 + rng.integers(-2, 3, (height, width, 3))
    contrast = np.interp(np.arange(width), [12, 80, 212], [strong_end, 4.0, 4.0])
    rgb[61:63] -= contrast[None, :, None]
    labels = np.zeros((height, width), dtype=np.int32)
    labels[12:112, 12:212] = 1
    rows, cols = np.mgrid[0:height, 0:width]
    points = np.stack([cols * 0.001, rows * 0.001, np.zeros((height, width))], axis=2)
    normals = np.zeros((height, width, 3), dtype=np.float32)
    normals[labels > 0] = (0.0, 0.0, 1.0)
    depth = np.where(labels > 0, 1.0, 0.0).astype(np.float32)
    K = np.array([[1000.0, 0.0, width / 2], [0.0, 1000.0, height / 2], [0.0, 0.0, 1.0]])
    return labels, rgb.astype(np.uint8), points.astype(np.float32), normals, depth, K


def test_a_seam_whose_edge_fades_still_cuts_from_outline_to_outline():
    # Strong at one end, faint along the rest: the faint stretch continues the strong edge
    # (hysteresis), so the seam crosses the face; counted as strong edges only, its stretch
    # stops a third of the way along and cannot cut.
    without = replace(PAIRS, seams=replace(PAIRS.seams, hysteresis=False))
    assert len(np.unique(cut_colour_seams(*faded_seam(80.0), PAIRS))) == 3  # 0 and 2 pieces
    assert len(np.unique(cut_colour_seams(*faded_seam(80.0), without))) == 2


def test_a_lone_seam_needs_both_strips_of_one_pair_elsewhere_to_match_both_ways():
    # A can's straight line along its axis (strips 10 x 3 cm each side) against a printed box's
    # lone seam elsewhere (strips 10.9 x 3.9 and 10.9 x 4.8 cm): one of the box's strips is
    # within 1 cm of both of the can's, the other of neither. Two pairs of one product match
    # both ways.
    seam = flat_seam(0.0)
    seam = replace(seam, half_length_m=0.05)
    no_faces = np.zeros((0, 2))

    def sized(pair: tuple) -> bool:
        pairs = np.array([pair], dtype=np.float64).reshape(-1, 2, 2)
        return _sized_like(seam, (0.03, 0.03), _Sizes(lambda: (no_faces, pairs)), ON)

    assert not sized(((0.109, 0.039), (0.109, 0.048)))
    assert sized(((0.105, 0.035), (0.101, 0.028)))
    # A face of the strips' size still suffices alone.
    faces = np.array([[0.1, 0.031]])
    assert _sized_like(seam, (0.03, 0.03), _Sizes(lambda: (faces, np.zeros((0, 2, 2)))), ON)


def test_an_unmoved_segment_keeps_the_previous_frames_seams():
    """A seam the previous frame did not cut does not cut the same unmoved surface now (a
    printed line that one frame's pass missed and the next found), but it does cut a surface
    that moved, and every surface with ``seams.settled`` off."""
    plain = two_boxes(lambda points: np.zeros(len(points), dtype=bool))
    first = segment_frame(plain, config=PAIRS)
    a, b = centres(first.labels, plain)
    assert a > 0 and a == b  # no edge, no seam: one segment
    still = two_boxes(gap_between)
    still = Frame(1, still.rgb, still.depth_m, still.K, still.world_from_camera)
    a, b = centres(segment_frame(still, config=PAIRS, previous=(plain, first)).labels, still)
    assert a > 0 and a == b
    unsettled = replace(PAIRS, seams=replace(PAIRS.seams, settled=False))
    a, b = centres(segment_frame(still, config=unsettled, previous=(plain, first)).labels, still)
    assert a > 0 and b > 0 and a != b
    # The same two boxes moved 15 cm along x, off their old place (a top slid by less would
    # leave pixels at an unchanged depth): the seam is searched.
    boxes = [box(0.15, -0.05, (0.1, 0.1, TOP)), box(0.15, 0.05, (0.1, 0.1, TOP))]
    moved = painted(render(camera(), boxes, noise_m=0.0005), gap_between)
    moved = Frame(1, moved.rgb, moved.depth_m, moved.K, moved.world_from_camera)
    labels = segment_frame(moved, config=PAIRS, previous=(plain, first)).labels
    a = segment_of_point(moved, labels, [0.15, -0.05, TOP])
    b = segment_of_point(moved, labels, [0.15, 0.05, TOP])
    assert a > 0 and b > 0 and a != b


def test_settled_segments_are_those_mostly_anchored_to_one_previous_segment():
    """A segment is settled when at least ``temporal.static_fraction`` of its pixels lie in
    supervoxels anchored to one previous segment (two previous segments' anchors do not add
    up), never the background."""
    from ipr_shapes.perception.segmentation import settled_segments
    from ipr_shapes.perception.temporal import SupervoxelChange
    from ipr_shapes.perception.types import Supervoxels

    labels = np.zeros((4, 10), dtype=np.int32)
    labels[:, 0:5] = 1
    labels[:, 5:10] = 2
    # Supervoxels: columns in pairs (0-1, 2-3, ...), 5 of them; -1 none.
    voxel = np.repeat(np.arange(5), 2)[None, :].repeat(4, axis=0).astype(np.int32)
    # Segment 1: columns 0-3 anchored to previous segment 7 (80 %), column 4 free (voxel 2).
    # Segment 2: column 5 free, 6-7 anchored to 8, 8-9 to 9: 80 % anchored, 40 % to one.
    anchor = np.array([7, 7, 0, 8, 9], dtype=np.int32)
    change = SupervoxelChange(anchor, np.zeros(5, np.int64), np.zeros(5, np.int64))
    supervoxels = Supervoxels(voxel, np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)),
                              np.full(5, 8), np.zeros((0, 2), dtype=np.int64))  # fmt: skip
    config = PerceptionConfig()
    for fraction, expected in ((0.75, [False, True, False]), (0.85, [False, False, False])):
        temporal = replace(config.temporal, static_fraction=fraction)
        settled = settled_segments(labels, supervoxels, change, replace(config, temporal=temporal))
        assert settled.tolist() == expected


def test_the_seams_pixel_kernels_are_scipys():
    """Exact: the components (numbered as scipy numbers them) and the erosion of the search."""
    from scipy import ndimage

    from ipr_shapes.perception import kernels

    rng = np.random.default_rng(5)
    for trial in range(300):
        mask = rng.random(tuple(rng.integers(1, 30, 2))) < rng.uniform(0.3, 1.0)
        if trial % 5 == 0:
            mask[:] = True
        labels, count = kernels.label_four_connected(mask)
        expected, expected_count = ndimage.label(mask)
        assert count == expected_count and np.array_equal(labels, expected)
        for radius in (1, 2, 3):
            eroded = kernels.erode_diamond(mask, radius)
            assert np.array_equal(eroded, ndimage.binary_erosion(mask, iterations=radius))
            sparse = mask & (rng.random(mask.shape) < 0.05)
            dilated = kernels.dilate_diamond(sparse, radius)
            assert np.array_equal(dilated, ndimage.binary_dilation(sparse, iterations=radius))
        square = ndimage.binary_dilation(sparse, np.ones((3, 3), dtype=bool))
        assert np.array_equal(_dilate_square(sparse), square)


def test_the_compiled_thinning_is_the_numpy_one():
    """Exact, rounding ties included (directions at odd multiples of 22.5 degrees)."""
    from ipr_shapes.perception.seams import _thin, _thin_numpy

    rng = np.random.default_rng(6)
    quarter = np.float32(np.pi / 4)
    for trial in range(200):
        height, width = rng.integers(1, 30, 2)
        magnitude = rng.random((height, width)).astype(np.float32)
        if trial % 3 == 0:
            magnitude = np.round(magnitude * 4).astype(np.float32) / 4  # equal neighbours
        direction = rng.uniform(-np.pi, np.pi, (height, width)).astype(np.float32)
        if trial % 2 == 0:
            halves = (rng.integers(-8, 9, (height, width)) / 2).astype(np.float32)
            direction = quarter * halves  # float32: direction / quarter is exactly the halves
        at = np.flatnonzero(rng.random(height * width) < 0.6)
        assert np.array_equal(
            _thin(magnitude, direction, at), _thin_numpy(magnitude, direction, at)
        )


def test_thinning_in_the_gradients_sectors_is_the_thinning_of_its_directions():
    """``_thin`` given the gradient's components (sectors read from them, the arctangent only
    near a boundary) is ``_thin_numpy`` of the float32 ``np.arctan2`` directions, at random
    gradients, on the axes and the diagonals, and at angles within 1e-7 to 1e-3 rad of the
    sectors' boundaries (odd multiples of 22.5 deg); the directions it measured are numpy's."""
    from ipr_shapes.perception.seams import _thin, _thin_numpy

    rng = np.random.default_rng(8)
    for trial in range(200):
        height, width = rng.integers(1, 30, 2)
        magnitude = rng.random((height, width)).astype(np.float32)
        if trial % 3 == 0:
            magnitude = np.round(magnitude * 4).astype(np.float32) / 4  # equal neighbours
        angle = rng.uniform(-np.pi, np.pi, (height, width))
        if trial % 2 == 0:  # near a boundary, on it, or on an axis or a diagonal
            near = np.pi / 8 * rng.integers(-8, 9, (height, width))
            offset = rng.choice([0.0, 1e-7, 3e-6, 1e-4, 1e-3], (height, width))
            angle = near + offset * rng.choice([-1.0, 1.0], (height, width))
        length = rng.uniform(0.01, 3.0, (height, width))
        gx = (length * np.cos(angle)).astype(np.float32)
        gy = (length * np.sin(angle)).astype(np.float32)
        if trial % 5 == 0:  # exact zeros of one component, signed
            gx[rng.random((height, width)) < 0.2] = -0.0
            gy[rng.random((height, width)) < 0.2] = 0.0
            gy[(gx == 0) & (gy == 0)] = 1.0
        direction = np.arctan2(gy, gx)
        at = np.flatnonzero(rng.random(height * width) < 0.6)
        measured = np.zeros_like(magnitude)
        thinned = _thin(magnitude, measured, at, gx, gy)
        assert np.array_equal(thinned, _thin_numpy(magnitude, direction, at))
        written = measured != 0
        assert np.array_equal(measured[written], direction[written])


def test_linked_pixels_are_the_components_that_hold_a_seed():
    """Exact: scipy's 8-connected components of ``pixels`` that hold a seed pixel."""
    from scipy import ndimage

    from ipr_shapes.perception import kernels

    rng = np.random.default_rng(7)
    for _ in range(200):
        shape = tuple(rng.integers(1, 40, 2))
        pixels = rng.random(shape) < rng.uniform(0.1, 0.6)
        seeds = rng.random(shape) < 0.05
        parts, count = ndimage.label(pixels, np.ones((3, 3), dtype=bool))
        holds = np.zeros(count + 1, dtype=bool)
        holds[parts[seeds]] = True
        holds[0] = False
        assert np.array_equal(kernels.linked_to(pixels, seeds), holds[parts])


def _surface(shape: tuple[int, int], point_and_normal) -> tuple[np.ndarray, np.ndarray]:
    """(h, w, 3) points and unit normals of a surface sampled on a grid of pixels: ``point_and
    _normal(u, v)`` maps the (h, w) grid coordinates u (rows), v (cols) in metres to both."""
    v, u = np.meshgrid(np.arange(shape[1]) * 0.001, np.arange(shape[0]) * 0.001)
    points, normals = point_and_normal(u, v)
    return points.astype(np.float32), normals.astype(np.float32)


def test_only_a_segment_with_a_flat_face_for_a_seam_and_two_strips_is_searched():
    """The search's gate (``seams.flat_face_gate``): a flat face at least ``min_length_m`` by
    twice ``min_width_m`` (a box's 10 x 10 cm top; a box seen over its edge, two faces of
    6 x 10 cm), and not a soup can's side (its normals within 15 deg of one span 1.7 cm) or a
    3 cm wide flat strip (no room for a strip of 2 cm on each side of a seam)."""
    from ipr_shapes.perception.seams import _GATE_POINTS, Normals, _has_flat_face

    def plane(width_m: float):
        shape = (100, round(width_m * 1000))
        up = np.zeros((*shape, 3))
        up[..., 2] = 1.0
        return shape, lambda u, v: (np.stack([u, v, np.zeros_like(u)], axis=-1), up)

    def can(u, v):  # radius 3.3 cm, axis along u, seen over 160 deg of its side
        angle = (v / 0.1 - 0.5) * np.radians(160.0)
        normal = np.stack([np.zeros_like(u), np.sin(angle), np.cos(angle)], axis=-1)
        return np.stack([u, 0.033 * np.sin(angle), 0.033 * np.cos(angle)], axis=-1), normal

    def edge(u, v):  # two faces meeting at v = 6 cm
        top = v < 0.06
        normal = np.where(top[..., None], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
        points = np.stack([u, np.minimum(v, 0.06), np.where(top, 0.0, 0.06 - v)], axis=-1)
        return points, normal

    for shape, surface, expected in (
        (*plane(0.10), True),
        ((100, 120), edge, True),
        ((100, 100), can, False),
        (*plane(0.03), False),
    ):
        points, values = _surface(shape, surface)
        mask = np.ones(shape, dtype=bool)
        # The normals computed on demand: the gate reads a sample of the segment only.
        asked = []

        def compute(flat, values=values, asked=asked):
            asked.append(len(flat))
            return values.reshape(-1, 3)[flat]

        normals = Normals(compute, mask)
        whole = (slice(0, shape[0]), slice(0, shape[1]))
        assert _has_flat_face(mask, whole, points, normals, ON) is expected
        assert 0 < sum(asked) <= _GATE_POINTS < mask.sum()
        assert np.array_equal(normals.everywhere(), values)
    # Unknown normals (no depth) are no face.
    points, values = _surface(*plane(0.10))
    whole = (slice(0, 100), slice(0, 100))
    mask = np.ones((100, 100), bool)
    assert not _has_flat_face(mask, whole, points, Normals.of(0 * values), ON)
    # Off: the can is searched (``cut_colour_seams`` asks the gate only when it is on).
    assert not replace(ON.seams, flat_face_gate=False).flat_face_gate


def test_a_trial_cut_without_room_for_two_pieces_is_skipped():
    """``_Room.fits``: the half-planes' footprints and extents bound the pieces of a convex
    part; a line 1 cm from a 10 x 6 cm part's side (a sliver narrower than ``min_width_m``)
    has no room, its middle has. ``kernels.line_sides`` is the brute-force half-plane sums."""
    from ipr_shapes.perception import kernels
    from ipr_shapes.perception.seams import _Room

    part = np.zeros((80, 120), dtype=bool)
    part[10:70, 10:110] = True
    depth = np.full(part.shape, 0.5)
    depth[20, 30] = 0.0  # filled with the median
    room = _Room(part, (slice(0, 80), slice(0, 120)), depth, 500.0)  # 1 mm per px
    assert room.fits(1.0, 0.0, 60.0, ON)  # x = 60: two 5 x 6 cm halves
    assert not room.fits(1.0, 0.0, 19.0, ON)  # x = 19: a 1 cm sliver
    assert not room.fits(0.0, 1.0, 15.0, ON)  # y = 15: a 0.5 cm sliver
    rng = np.random.default_rng(8)
    rows, cols = np.nonzero(part)
    for _ in range(20):
        angle, rho = rng.uniform(0, np.pi), rng.uniform(0, 120)
        sides = kernels.line_sides(rows.astype(np.int64), cols.astype(np.int64),
                                   np.full(len(rows), 1e-6), np.full(len(rows), 1e-3),
                                   np.cos(angle), np.sin(angle), rho)  # fmt: skip
        distance = cols * np.cos(angle) + rows * np.sin(angle) - rho
        along = -cols * np.sin(angle) + rows * np.cos(angle)
        for side, chosen in enumerate((distance > 0, distance <= 0)):
            if not chosen.any():
                assert np.all(sides[side] == 0)
                continue
            assert sides[side, 0] == pytest.approx(chosen.sum() * 1e-6)
            assert sides[side, 1] == pytest.approx((np.abs(distance[chosen]).max() + 0.5) * 1e-3)
            spread = np.ptp(along[chosen]) + 1.0
            assert sides[side, 2] == pytest.approx(spread * 1e-3)


def test_the_compiled_room_is_numpys():
    """``_Room`` on float32 depths (``kernels.room_pixels``) gives the numbers of its numpy
    path (the same depths as float64): pixels row-major, sizes with missing depths filled by
    the median of the others (odd and even counts, ties, none known), footprints."""
    from ipr_shapes.perception.seams import _Room

    rng = np.random.default_rng(14)
    for trial in range(300):
        height, width = (int(n) for n in rng.integers(1, 40, 2))
        part = rng.random((height, width)) < rng.uniform(0.05, 1.0)
        depth = rng.uniform(0.3, 1.2, (height, width)).astype(np.float32)
        if trial % 3 == 0:
            depth = np.round(depth, 2).astype(np.float32)  # ties
        depth[rng.random((height, width)) < rng.uniform(0.0, 1.0)] = 0.0
        if trial % 7 == 0:
            depth[:] = 0.0
        window = (slice(0, height), slice(0, width))
        compiled = _Room(part, window, depth, 500.0)
        reference = _Room(part, window, depth.astype(np.float64), 500.0)
        for name in ("rows", "cols", "size", "foot"):
            assert np.array_equal(getattr(compiled, name), getattr(reference, name))


def test_the_screens_room_test_that_stops_early_answers_as_the_full_sums():
    """``kernels.line_sides_fit`` (the candidate screen's room test, which stops once every
    test holds) answers as ``line_sides``' full sums compared as ``_Room.fits`` does, on
    random parts, lines and thresholds, empty sides and zero thresholds included."""
    from ipr_shapes.perception import kernels

    rng = np.random.default_rng(11)
    answers = set()
    for trial in range(400):
        count = int(rng.integers(1, 2000))
        rows = np.sort(rng.integers(0, 200, count)).astype(np.int64)
        cols = rng.integers(0, 200, count).astype(np.int64)
        size = rng.uniform(0.5e-3, 2e-3, count)
        foot = size**2
        angle, rho = rng.uniform(0, np.pi), rng.uniform(-50, 280)
        min_area = 0.0 if trial % 7 == 0 else float(rng.uniform(0, 2 * foot.sum()))
        min_width = 0.0 if trial % 5 == 0 else float(rng.uniform(0, 0.3))
        sides = kernels.line_sides(rows, cols, foot, size, np.cos(angle), np.sin(angle), rho)
        expected = bool(
            np.all(sides[:, 0] >= min_area)
            and np.all(np.minimum(sides[:, 1], sides[:, 2]) >= min_width)
        )
        fit = kernels.line_sides_fit(rows, cols, foot, size, np.cos(angle), np.sin(angle), rho,
                                     min_area, min_width)  # fmt: skip
        assert fit == expected
        answers.add(expected)
    assert answers == {True, False}


def test_the_noise_median_is_numpys_median():
    """``_masked_median``: ``np.median`` of the values at the mask, the same float, in their
    float32 and in float64, for odd and even counts, ties, zeros and one value."""
    from ipr_shapes.perception.seams import _masked_median

    rng = np.random.default_rng(12)
    for trial in range(300):
        shape = tuple(int(n) for n in rng.integers(1, 40, 2))
        values = (rng.random(shape) * 10 ** rng.uniform(-3, 2)).astype(np.float32)
        if trial % 3 == 0:
            values = np.round(values, 1).astype(np.float32)  # ties
        values[rng.random(shape) < 0.2] = 0.0
        mask = rng.random(shape) < rng.uniform(0.05, 1.0)
        mask.flat[int(rng.integers(mask.size))] = True
        assert _masked_median(values, mask) == float(np.median(values[mask]))
        wide = float(np.median(values[mask].astype(np.float64)))
        assert _masked_median(values, mask, np.float64) == wide
        assert _masked_median(values[mask]) == float(np.median(values[mask]))


def test_the_gradient_in_the_searched_crops_is_the_frames_and_the_noise_its_median():
    """``_colour_gradient_in``: the frame's gradient, number for number, in each crop and a
    1 px ring (frame borders included), 0 elsewhere; ``kernels.colour_gradient_at``: the
    frame's magnitude at any pixel; ``_edge_noise``: the median over pixels with depth within
    a few percent from its sample."""
    from ipr_shapes.perception import kernels
    from ipr_shapes.perception.seams import (
        _GAUSSIAN,
        _colour_gradient,
        _colour_gradient_in,
        _edge_noise,
    )

    rng = np.random.default_rng(9)
    rgb = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    rgb = (rgb // 32 * 32).astype(np.uint8)
    magnitude, gx, gy = _colour_gradient(rgb)
    crops = [(slice(0, 30), slice(5, 50)), (slice(60, 120), slice(100, 160))]
    local, local_x, local_y, whole = _colour_gradient_in(rgb, crops)
    assert not whole
    ring = np.zeros(magnitude.shape, dtype=bool)
    for rows, cols in crops:
        ring[max(rows.start - 1, 0) : rows.stop + 1, max(cols.start - 1, 0) : cols.stop + 1] = True
    for got, expected in ((local, magnitude), (local_x, gx), (local_y, gy)):
        assert np.array_equal(got[ring], expected[ring])
        assert not got[~ring].any()
    # Crops over most of the frame: the frame's gradient.
    assert _colour_gradient_in(rgb, [(slice(0, 120), slice(0, 150))])[3]
    rows, cols = np.nonzero(np.ones(magnitude.shape, dtype=bool))
    at = kernels.colour_gradient_at(rgb, _GAUSSIAN, rows.astype(np.int64), cols.astype(np.int64))
    assert np.allclose(at, magnitude.ravel(), atol=1e-5)
    depth = np.where(rng.random(magnitude.shape) < 0.8, 0.7, 0.0)
    noise = _edge_noise(rgb, depth, np.ones(depth.shape, dtype=bool))
    assert noise == pytest.approx(float(np.median(magnitude[depth > 0])), rel=0.05)


def test_the_frames_faces_are_read_only_until_both_strips_match():
    """A lone seam's strips (10 x 3 and 10 x 4 cm) each need a face of their size elsewhere,
    possibly in two segments; the segments' faces are measured one by one, and no further once
    both matched."""
    strips = np.array([[0.10, 0.03], [0.10, 0.04]])
    read = []

    def segments(*chunks):
        for chunk in chunks:
            read.append(len(read))
            if chunk is None:
                raise AssertionError("read past the match")
            yield np.array(chunk, dtype=np.float64).reshape(-1, 2)

    assert _covered(strips, segments([[0.2, 0.2]], [[0.104, 0.028]], [[0.1, 0.045]], None), 0.01)
    assert read == [0, 1, 2]
    read.clear()
    # One strip matched in every segment, the other in none: every segment is read.
    assert not _covered(strips, segments([[0.1, 0.03]], [], [[0.1, 0.029]]), 0.01)
    assert read == [0, 1, 2]


def test_a_frame_with_no_seam_cut_is_segmented_as_without_the_seams():
    """Labels, their numbering and the supervoxels' segments: the seams change nothing where
    they cut nothing (two boxes of different heights, one plain box elsewhere)."""
    boxes = [box(0.0, -0.06, (0.1, 0.1, TOP)), box(0.0, 0.06, (0.1, 0.1, 0.1)),
             box(0.15, 0.0, (0.05, 0.05, 0.03))]  # fmt: skip
    frame = painted(render(camera(), boxes, noise_m=0.0005), lambda p: p[:, 0] > 0.12)
    off, on = segment_frame(frame), segment_frame(frame, config=ON)
    assert off.labels.max() >= 3
    assert np.array_equal(on.labels, off.labels)
    assert np.array_equal(on.segment_of_supervoxel, off.segment_of_supervoxel)
    # Whatever the numbering (here the reverse of the segments' sizes): not renumbered.
    flipped = np.where(off.labels > 0, off.labels.max() + 1 - off.labels, 0)
    owners = np.where(off.segment_of_supervoxel > 0,
                      off.labels.max() + 1 - off.segment_of_supervoxel, 0)  # fmt: skip
    points = frame.points_world().reshape(*frame.depth_m.shape, 3)
    labels, segments = _cut_seams(flipped, off.supervoxels, frame, points, ON, None, owners)
    assert np.array_equal(labels, flipped) and np.array_equal(segments, owners)


def test_an_area_test_decided_by_its_bounds_is_the_area_compared():
    """``_has_area`` answers as ``_area_m2 >= area`` does, whether the bounds (the pixels
    without depth at the smallest or the largest depth) decide or the median has to."""
    rng = np.random.default_rng(8)
    decided_by_median = 0
    for _ in range(400):
        depth = rng.uniform(0.5, 1.5, (20, 20)).astype(np.float32)
        depth[rng.random(depth.shape) < rng.uniform(0.0, 0.6)] = 0.0
        part = rng.random(depth.shape) < 0.7
        area = _area_m2(part, depth, 600.0)
        for threshold in (0.5 * area, 0.98 * area, area, 1.02 * area, 2.0 * area):
            assert _has_area(part, depth, 600.0, threshold) == (area >= threshold)
        known = depth[part][depth[part] > 0]
        missing = int((depth[part] == 0).sum())
        base = float(np.sum(known.astype(np.float64) ** 2))
        if missing and known.size:
            low = (base + missing * float(known.min()) ** 2) / 600.0**2
            high = (base + missing * float(known.max()) ** 2) / 600.0**2
            decided_by_median += low < area < high
    assert decided_by_median > 100


def test_the_compiled_screen_of_candidate_seams_is_the_room_and_side_band_tests():
    """``kernels.seam_screen`` finds, from any start, the first candidate line that has room
    for two pieces (``_Room.fits``) and whose side bands have one normal (``_coplanar_sides``
    without its step test); ``kernels.stretch_lengths`` is numpy's length between a stretch's
    outermost pixels with depth. A part whose left third is tilted by 30 degrees: lines along
    the crease fail the normals, lines near the border the room."""
    from ipr_shapes.perception import kernels
    from ipr_shapes.perception.seams import _SIDE_BAND_PX, _coplanar_sides, _Room

    rng = np.random.default_rng(11)
    height, width = 60, 90
    part = np.zeros((height, width), dtype=bool)
    part[5:55, 5:85] = True
    part[rng.random(part.shape) < 0.03] = False
    depth = rng.uniform(0.45, 0.55, part.shape).astype(np.float32)
    depth[rng.random(part.shape) < 0.05] = 0.0
    rows_px, cols_px = np.mgrid[0:height, 0:width]
    points = np.stack([cols_px * 1e-3, rows_px * 1e-3, depth], axis=2).astype(np.float32)
    normals = np.zeros((height, width, 3), dtype=np.float32)
    normals[..., 2] = 1.0
    tilt = np.radians(30.0)
    normals[:, :30] = (np.sin(tilt), 0.0, np.cos(tilt))
    normals += rng.normal(0.0, 0.02, normals.shape).astype(np.float32)
    normals[~part] = 0.0
    room = _Room(part, (slice(0, height), slice(0, width)), depth, 500.0)
    has_normal = part & np.any(normals != 0, axis=2)
    part_pixels = tuple(axis.astype(np.int64) for axis in np.nonzero(has_normal))
    # Candidate lines: vertical ones across the part (the crease at x = 30, slivers at the
    # border) and oblique ones; each stretch the part's pixels within half a pixel of it.
    lines = [(0.0, x) for x in (7.0, 29.5, 30.0, 45.0, 60.0, 83.0)]
    lines += [(rng.uniform(0, np.pi), rng.uniform(10, 80)) for _ in range(30)]
    cos_l = np.array([np.cos(angle) for angle, _ in lines])
    sin_l = np.array([np.sin(angle) for angle, _ in lines])
    rho_l = np.array([rho for _, rho in lines])
    stretch_rows, stretch_cols, bounds = [], [], [0]
    for cos_a, sin_a, rho in zip(cos_l, sin_l, rho_l, strict=True):
        on = part & (np.abs(cols_px * cos_a + rows_px * sin_a - rho) <= 0.5)
        r, c = np.nonzero(on)
        stretch_rows.append(r)
        stretch_cols.append(c)
        bounds.append(bounds[-1] + len(r))
    stretch_rows = np.concatenate(stretch_rows).astype(np.int64)
    stretch_cols = np.concatenate(stretch_cols).astype(np.int64)
    bounds = np.array(bounds, dtype=np.int64)
    no_step = replace(ON, seams=replace(ON.seams, max_step_m=1e9))
    expected = []
    for k in range(len(lines)):
        r, c = stretch_rows[bounds[k] : bounds[k + 1]], stretch_cols[bounds[k] : bounds[k + 1]]
        ok = len(r) > 0 and room.fits(cos_l[k], sin_l[k], rho_l[k], ON)
        ok = ok and _coplanar_sides(part_pixels, part.shape, r, c, cos_l[k], sin_l[k],
                                    rho_l[k], points, normals, no_step) is not None  # fmt: skip
        expected.append(ok)
    assert 3 <= sum(expected) < len(lines) - 3  # both ways
    assert not expected[1] and not expected[2] and not expected[0] and expected[4]
    which = np.array([k for k in range(len(lines)) if bounds[k + 1] > bounds[k]], np.int64)
    near, far = _SIDE_BAND_PX
    found, screened = -1, []
    while True:
        found = kernels.seam_screen(which, cos_l, sin_l, rho_l, stretch_rows, stretch_cols,
                                    bounds, room.rows, room.cols, room.foot, room.size,
                                    ON.seams.min_area_m2, ON.seams.min_width_m, *part_pixels,
                                    height, width, float(near), float(far), normals,
                                    ON.seams.max_normal_deg, found + 1)  # fmt: skip
        if found < 0:
            break
        screened.append(int(which[found]))
    assert screened == [k for k in which if expected[k]]
    lengths = kernels.stretch_lengths(stretch_rows, stretch_cols, bounds, which, depth, points)
    for k, length in zip(which, lengths, strict=True):
        r, c = stretch_rows[bounds[k] : bounds[k + 1]], stretch_cols[bounds[k] : bounds[k + 1]]
        measured = np.flatnonzero(depth[r, c] > 0)
        if measured.size < 2:
            assert length == -1.0
            continue
        ends = points[r[measured[[0, -1]]], c[measured[[0, -1]]]]
        assert length == pytest.approx(float(np.linalg.norm(ends[0] - ends[1])), rel=1e-6)


def test_row_percentiles_are_numpys_bits():
    """The face sizes' rectangle (``_face_size``): percentiles from sorted rows, the same bits as
    ``np.percentile`` (linear method; ties, both ends, gamma below and above a half)."""
    rng = np.random.default_rng(5)
    for trial in range(300):
        count = int(rng.integers(2, 3000))
        rows = rng.normal(size=(int(rng.integers(1, 6)), count)) * 10 ** rng.uniform(-3, 1)
        if trial % 3 == 0:
            rows = np.round(rows, 2)  # ties
        percents = (2.0, 98.0) if trial % 2 else (0.0, 100.0, *rng.uniform(0, 100, 4))
        assert np.array_equal(
            _row_percentiles(rows, percents), np.percentile(rows, percents, axis=1)
        )


def test_single_percentiles_are_numpys():
    """``_percentiles`` (a face's bend, a strip's width, a piece's span): ``np.percentile``'s
    floats in float64 (from a sorted row) and float32 (numpy's own), one value to thousands."""
    from ipr_shapes.perception.seams import _percentiles

    rng = np.random.default_rng(13)
    for trial in range(200):
        count = int(rng.integers(1, 3000)) if trial % 4 else int(rng.integers(1, 4))
        dtype = np.float32 if trial % 5 == 0 else np.float64
        values = (rng.normal(size=count) * 10 ** rng.uniform(-3, 1)).astype(dtype)
        if trial % 3 == 0:
            values = np.round(values, 2).astype(dtype)  # ties
        for percents in ((90.0,), (98.0,), (98.0, 2.0)):
            expected = [float(value) for value in np.percentile(values, percents)]
            assert _percentiles(values, percents) == expected


def test_the_frames_faces_skip_pieces_too_small_for_a_strip():
    """Strips 19 cm long need faces at least 18 cm long: a 6 cm piece's face is never
    measured, and the answer is the one from measuring every face."""
    height, width = 60, 80
    yy, xx = np.mgrid[0:height, 0:width]
    points = np.stack([xx * 0.004, yy * 0.004, np.full(xx.shape, 0.5)], axis=-1).astype(np.float32)
    normals = np.zeros((height, width, 3), dtype=np.float32)
    normals[..., 2] = 1.0
    depth = np.full((height, width), 0.5)
    frame = (slice(0, height), slice(0, width))
    small = np.zeros((height, width), dtype=bool)
    small[2:17, 2:17] = True  # 6 x 6 cm
    large = np.zeros((height, width), dtype=bool)
    large[10:58, 20:70] = True  # 19 x 20 cm (its face: 19 x 19 cm, 2nd to 98th percentile)
    searched = [(frame, mask, mask.astype(np.int32), [], np.empty((0, 3)), [])
                for mask in (small, large, small)]  # fmt: skip
    decided = [entry[2] for entry in searched]
    config = PerceptionConfig()
    faces = _FrameFaces(searched, decided, points, Normals.of(normals), depth, config)
    measured = []
    size = faces.size
    faces.size = lambda index, piece: measured.append(index) or size(index, piece)
    tolerance = config.seams.size_tolerance_m
    strips = np.array([[0.19, 0.185], [0.19, 0.185]])
    assert faces.reach(0)[1] < 0.09 and faces.reach(1)[1] > 0.25
    assert _covered(strips, _FacesElsewhere(faces, 2), tolerance)
    assert measured == [1]
    assert _covered(strips, list(_FacesElsewhere(faces, 2)), tolerance)
    # A strip the small piece's size: its face is measured.
    measured.clear()
    strips = np.array([[0.056, 0.056], [0.056, 0.056]])
    assert _covered(strips, _FacesElsewhere(faces, 2), tolerance)
    assert 0 in measured
