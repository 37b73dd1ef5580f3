"""An object split in one frame and seen whole, moved, in the next is one id in every frame
(``tracking.join_moved_wholes``, opt-in ``TrackingConfig.moved_wholes``).

The frames are built from world points directly: which pixel holds a point does not matter to
the join, which reads the labelled points of each frame (m, world frame, z up).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ipr_shapes.perception.config import TrackingConfig
from ipr_shapes.perception.tracking import join_moved_wholes, rigid_registration

SHAPE = (40, 60)  # image rows, columns: room for every point below

ON = replace(TrackingConfig(), moved_wholes=True)


def _box_surface(origin: tuple[float, float, float], size: tuple[float, float, float]):
    """(N, 3) points (m) on a box's top and two of its sides, 5 mm apart: a surface that one
    rigid motion registers without sliding."""
    x0, y0, z0 = origin
    dx, dy, dz = size
    step = 0.005
    xs, ys, zs = np.arange(0, dx, step), np.arange(0, dy, step), np.arange(0, dz, step)
    top = [(x0 + x, y0 + y, z0 + dz) for x in xs for y in ys]
    front = [(x0 + x, y0, z0 + z) for x in xs for z in zs]
    side = [(x0, y0 + y, z0 + z) for y in ys for z in zs]
    return np.array(top + front + side)


def _frame(pieces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(H, W) labels 1, 2, ... for each (N_k, 3) point set, (H, W, 3) points, (H, W) depth."""
    labels = np.zeros(SHAPE[0] * SHAPE[1], dtype=np.int32)
    points = np.zeros((SHAPE[0] * SHAPE[1], 3))
    start = 0
    for label, piece in enumerate(pieces, start=1):
        labels[start : start + len(piece)] = label
        points[start : start + len(piece)] = piece
        start += len(piece)
    assert start <= labels.size
    depth = np.where(labels > 0, 0.6, 0.0).reshape(SHAPE)
    return labels.reshape(SHAPE), points.reshape(SHAPE + (3,)), depth


def _moved(points: np.ndarray, angle_deg: float, shift: tuple[float, float, float]):
    """(N, 3) points turned by ``angle_deg`` about the vertical through their centroid and
    shifted by ``shift`` (m): a push."""
    angle = np.radians(angle_deg)
    rotation = np.array(
        [[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0, 0, 1]]
    )
    centre = points.mean(axis=0)
    return (points - centre) @ rotation.T + centre + np.asarray(shift)


def _run(frames, config=ON):
    labels, points, depth = zip(*frames, strict=True)
    return join_moved_wholes(list(labels), list(points), list(depth), config)


def test_registration_recovers_a_push():
    box = _box_surface((0.0, 0.0, 0.0), (0.10, 0.06, 0.04))
    pushed = _moved(box, 15.0, (0.04, 0.02, 0.0))
    rotation, translation = rigid_registration(pushed, box)
    # Within a grid step (5 mm; point-to-point ICP on a sampled surface), well inside the
    # 1 cm inlier distance the join tests with.
    assert np.abs(pushed @ rotation.T + translation - box).max() < 5e-3


def test_an_object_split_then_seen_whole_after_a_push_is_one_id():
    box = _box_surface((0.0, 0.0, 0.0), (0.10, 0.06, 0.04))
    left, right = box[box[:, 0] < 0.05], box[box[:, 0] >= 0.05]
    frame0 = _frame([left, right])  # split in frame 0 (a crease, a colour edge)
    frame1 = _frame([_moved(box, 15.0, (0.04, 0.02, 0.0))])  # whole, pushed, id of the left
    tracked = _run([frame0, frame1])
    assert set(np.unique(tracked[0])) == {0, 1}  # the right piece joined the left's id
    assert set(np.unique(tracked[1])) == {0, 1}
    # Off: unchanged.
    untouched = _run([frame0, frame1], TrackingConfig(moved_wholes=False))
    assert set(np.unique(untouched[0])) == {0, 1, 2}


def test_an_object_split_across_a_gap_is_joined_too():
    # Pieces 3 cm apart (an occluder hid the middle in frame 0).
    box = _box_surface((0.0, 0.0, 0.0), (0.12, 0.06, 0.04))
    left, right = box[box[:, 0] < 0.045], box[box[:, 0] >= 0.075]
    frame0 = _frame([left, right])
    frame1 = _frame([_moved(box, -10.0, (0.03, -0.03, 0.0))])
    assert set(np.unique(_run([frame0, frame1])[0])) == {0, 1}


def test_pieces_farther_apart_than_the_gap_are_not_joined():
    # The same cut box, its pieces 14 cm apart (more than ``whole_max_gap_m``, 10 cm): however
    # well the pushed whole covers both, they are not taken for one object.
    box = _box_surface((0.0, 0.0, 0.0), (0.26, 0.06, 0.04))
    left, right = box[box[:, 0] < 0.06], box[box[:, 0] >= 0.20]
    frame0 = _frame([left, right])
    frame1 = _frame([_moved(box, -10.0, (0.03, -0.03, 0.0))])
    assert set(np.unique(_run([frame0, frame1])[0])) == {0, 1, 2}
    # Within a wider gap the very same frames are joined: the gap alone decided.
    wider = replace(ON, whole_max_gap_m=0.2)
    assert set(np.unique(_run([frame0, frame1], wider)[0])) == {0, 1}


def test_a_neighbour_that_vanished_is_not_joined_to_a_pushed_object():
    # Two boxes side by side; the push moves the first, the second is hidden in frame 1. The
    # first's frame-1 surface, registered, covers its own frame-0 surface and not the second's.
    first = _box_surface((0.0, 0.0, 0.0), (0.08, 0.06, 0.04))
    second = _box_surface((0.085, 0.0, 0.0), (0.05, 0.05, 0.06))
    frame0 = _frame([first, second])
    frame1 = _frame([_moved(first, 15.0, (0.04, 0.02, 0.0))])
    assert set(np.unique(_run([frame0, frame1])[0])) == {0, 1, 2}


def test_an_object_that_did_not_move_gives_no_evidence():
    # The frame-1 segment covers both frame-0 segments in place: the segmentation may merely
    # have merged two objects there, so no join.
    box = _box_surface((0.0, 0.0, 0.0), (0.10, 0.06, 0.04))
    left, right = box[box[:, 0] < 0.05], box[box[:, 0] >= 0.05]
    frame0 = _frame([left, right])
    frame1 = _frame([box])
    assert set(np.unique(_run([frame0, frame1])[0])) == {0, 1, 2}
