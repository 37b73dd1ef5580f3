"""Joining pieces of one object cut apart by an occluder (ipr_shapes.perception.occlusion)."""

from __future__ import annotations

import numpy as np

from ipr_shapes.perception.config import OccludedPiecesConfig
from ipr_shapes.perception.free_space import VoxelGrid, observe_space
from ipr_shapes.perception.occlusion import join_occluded_pieces
from ipr_shapes.perception.tracking import segment_features
from ipr_shapes.perception.types import KnownPlane, PartialObject
from tests.test_segmentation import K, box, camera, render

SUPPORT = KnownPlane("support", np.array([0.0, 0.0, 1.0]), 0.0, np.zeros((0, 3)))


def _in_box(points: np.ndarray, spec, margin: float = 0.003) -> np.ndarray:
    centre, half, _ = spec
    return np.all(np.abs(points - centre) <= np.asarray(half) + margin, axis=-1)


def _objects(boxes, pieces):
    """Render ``boxes`` and cut their observed points into objects: ``pieces`` lists, per
    object, (box index, x range) of the points it takes. Returns the objects, their segment
    features and the frame's free-space map."""
    frame = render(camera(), boxes=boxes)
    points = frame.points_world()
    valid = frame.depth_m > 0
    labels = np.zeros(frame.shape, np.int32)
    objects = []
    for number, (index, (low, high)) in enumerate(pieces, start=1):
        mask = valid & _in_box(points, boxes[index]) & (points[..., 0] >= low)
        mask &= points[..., 0] < high
        labels[mask] = number
        pixels = np.flatnonzero(mask)
        objects.append(
            PartialObject(
                number, 0, pixels, points.reshape(-1, 3)[pixels], frame.rgb.reshape(-1, 3)[pixels]
            )
        )
    grid = VoxelGrid.around(np.array([-0.3, -0.3, 0.0]), np.array([0.3, 0.3, 0.25]))
    space = observe_space(frame.depth_m, K, frame.world_from_camera, grid)
    features = segment_features(labels, points, frame.rgb, frame.depth_m)
    return tuple(objects), features, space


def test_pieces_hidden_apart_by_an_occluder_are_joined_and_the_occluder_is_not():
    long_box = box(0.0, 0.0, (0.30, 0.08, 0.05))
    occluder = box(0.0, -0.12, (0.06, 0.04, 0.20))  # in front of the long box's middle
    objects, features, space = _objects(
        [long_box, occluder], [(0, (-1.0, -0.06)), (0, (-0.06, 1.0)), (1, (-1.0, 1.0))]
    )
    # The occluder really cuts the long box in two (seen from the camera on the +x side, the
    # band it hides is x in [-0.09, -0.03]): no observed point there.
    pieces = np.concatenate([o.points for o in objects[:2]])
    assert not (np.abs(pieces[:, 0] + 0.06) < 0.02).any()
    joined, joins = join_occluded_pieces(objects, features, space, (SUPPORT,))
    assert joins == [(1, 2)]
    assert [o.id for o in joined] == [1, 3]
    assert len(joined[0].points) == len(objects[0].points) + len(objects[1].points)
    # Switched off, nothing is joined.
    off = OccludedPiecesConfig(enabled=False)
    assert join_occluded_pieces(objects, features, space, (SUPPORT,), off)[1] == []


def test_alike_objects_with_the_table_seen_between_them_stay_apart():
    left, right = box(-0.08, 0.0, (0.08, 0.08, 0.05)), box(0.08, 0.0, (0.08, 0.08, 0.05))
    objects, features, space = _objects([left, right], [(0, (-1.0, 1.0)), (1, (-1.0, 1.0))])
    joined, joins = join_occluded_pieces(objects, features, space, (SUPPORT,))
    assert joins == [] and len(joined) == 2


def test_screened_inside_count_is_the_count_over_every_point():
    # Points in and around a hull, many within a few ulps of the margin-shrunk box and planes:
    # the bounding-box screen must keep every point the facets count.
    from scipy.spatial import ConvexHull

    from ipr_shapes.perception.occlusion import _points_inside

    rng = np.random.default_rng(3)
    hull_points = rng.normal(size=(60, 3)) * [0.05, 0.03, 0.04] + [0.2, -0.1, 0.05]
    points = rng.uniform(-0.1, 0.1, size=(4000, 3)) + [0.2, -0.1, 0.05]
    low, high = hull_points.min(axis=0), hull_points.max(axis=0)
    edge = np.repeat(rng.uniform(low, high, size=(50, 3)), 3, axis=0)
    for axis in range(3):  # on the faces of the box shrunk by the margin
        edge[axis::3, axis] = np.where(rng.random(50) < 0.5, low[axis], high[axis])
    points = np.concatenate([points, edge, edge + 0.002, edge - 0.002])
    equations = ConvexHull(hull_points).equations
    for margin in (0.0, 0.002, 0.005, 0.02):
        signed = points @ equations[:, :3].T + equations[:, 3]
        expected = int(np.count_nonzero(np.all(signed < -margin, axis=1)))
        assert _points_inside(points, hull_points, margin) == expected
    assert _points_inside(np.zeros((0, 3)), hull_points, 0.005) == 0


def test_screened_gap_test_is_the_test_over_every_pair():
    from ipr_shapes.perception.occlusion import _within

    rng = np.random.default_rng(4)
    a = rng.uniform(0.0, 0.1, size=(300, 3))
    for shift in (0.0, 0.05, 0.1, 0.15, 0.19, 0.2, 0.21, 0.3):
        b = rng.uniform(0.0, 0.1, size=(200, 3)) + [shift, 0.3 * shift, 0.0]
        gap = float(np.min(np.linalg.norm(a[:, None] - b[None, :], axis=-1)))
        for limit in (0.0, 0.01, 0.05, gap, np.nextafter(gap, 0.0), 0.1):
            assert _within(a, b, limit) == (gap <= limit), (shift, limit)
            assert _within(b, a, limit) == (gap <= limit), (shift, limit)


def test_a_pair_tested_once_is_not_tested_again_until_one_of_it_is_joined(monkeypatch):
    # Three boxes cut in two each, the pairs' colours set so that each pass over the pairs
    # tests all three before it joins the most alike: the passes after a join test no pair
    # again whose objects were not joined (three hull tests, not six), and the joins are
    # those of testing every pair every time.
    import ipr_shapes.perception.occlusion as occlusion

    boxes = [box(0.0, y, (0.30, 0.06, 0.05)) for y in (-0.2, 0.0, 0.2)]
    pieces = [(k, span) for k in range(3) for span in ((-1.0, -0.03), (0.03, 1.0))]
    objects, _, space = _objects(boxes, pieces)
    alike = {(1, 2): 0.3, (3, 4): 0.2, (5, 6): 0.1}  # other pairs: too far apart anyway
    monkeypatch.setattr(occlusion, "colour_distance", lambda a, b: alike.get((a, b), 0.5))
    monkeypatch.setattr(occlusion, "merged_features", lambda a, b: a)
    calls = []
    hull_inside = occlusion._points_inside
    monkeypatch.setattr(
        occlusion,
        "_points_inside",
        lambda points, hull, margin: calls.append(len(hull)) or hull_inside(points, hull, margin),
    )
    features = {o.id: o.id for o in objects}
    joined, joins = join_occluded_pieces(objects, features, space, (SUPPORT,))
    assert joins == [(5, 6), (3, 4), (1, 2)]
    assert [o.id for o in joined] == [1, 3, 5]
    assert len(calls) == 3
