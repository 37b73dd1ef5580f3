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
