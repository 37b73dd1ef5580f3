"""Temporal anchoring: unchanged surfaces keep the previous frame's grouping, moved ones do not."""

from __future__ import annotations

import numpy as np

from ipr_shapes.camera import backproject
from ipr_shapes.perception.config import PerceptionConfig, TemporalConfig
from ipr_shapes.perception.segmentation import anchor_parts
from ipr_shapes.perception.temporal import (
    ARRIVED,
    NOT_COMPARED,
    REVEALED,
    UNCHANGED,
    FrameChange,
    SupervoxelChange,
    compare_frames,
    consistent_walls,
    same_plane,
    supervoxel_anchors,
)
from ipr_shapes.perception.types import KnownPlane, Supervoxels

K = np.array([[100.0, 0.0, 20.0], [0.0, 100.0, 15.0], [0.0, 0.0, 1.0]])


def _world(depth: np.ndarray, world_from_camera: np.ndarray) -> np.ndarray:
    camera = backproject(depth, K)
    return camera @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]


def test_pixels_are_unchanged_revealed_arrived_or_not_compared():
    before = np.full((30, 40), 1.0, np.float32)
    labels = np.zeros((30, 40), np.int32)
    labels[:, :20] = 1
    labels[:, 20:] = 2
    after = before.copy()
    after[:, 20:25] = 1.2  # 2 moved away: the wall behind shows
    after[:, 25:30] = 0.8  # something arrived in front of 2
    after[:, 30:32] = 1.003  # noise within the tolerance
    after[:, 32:34] = 0.0  # no reading
    pose = np.eye(4)
    change = compare_frames(_world(after, pose), after, before, labels, K, pose, PerceptionConfig())
    assert (change.state[:, :20] == UNCHANGED).all() and (change.previous_label[:, :20] == 1).all()
    assert (change.state[:, 20:25] == REVEALED).all()
    assert (change.state[:, 25:30] == ARRIVED).all()
    assert (change.state[:, 30:32] == UNCHANGED).all()
    assert (change.state[:, 32:34] == NOT_COMPARED).all()
    assert (change.previous_label[:, 32:34] == 0).all()
    assert (change.previous_label[:, 20:32] == 2).all()
    # A fixed camera compares pixels in place, with the same result.
    in_place = compare_frames(
        _world(after, pose),
        after,
        before,
        labels,
        K,
        pose,
        PerceptionConfig(),
        K=K,
        world_from_camera=pose,
    )
    assert np.array_equal(in_place.state, change.state)
    assert np.array_equal(in_place.previous_label, change.previous_label)


def test_a_moving_camera_compares_the_same_surface_point():
    # A plane 1 m in front of both cameras; the second camera moved 5 cm along x, so the
    # plane's label boundary moves 5 px in the image (f = 100 px) and nothing changed.
    depth = np.full((30, 40), 1.0, np.float32)
    labels = np.zeros((30, 40), np.int32)
    labels[:, :20] = 1
    labels[:, 20:] = 2
    first_pose, second_pose = np.eye(4), np.eye(4)
    second_pose[0, 3] = 0.05
    change = compare_frames(
        _world(depth, second_pose), depth, depth, labels, K, first_pose, PerceptionConfig()
    )
    assert (change.state[:, :35] == UNCHANGED).all()
    assert (change.state[:, 35:] == NOT_COMPARED).all()  # outside the first image
    assert (change.previous_label[:, :15] == 1).all()
    assert (change.previous_label[:, 15:35] == 2).all()
    # From the depth and pixel grid when frame t's camera is given: the same comparison.
    from_grid = compare_frames(
        _world(depth, second_pose),
        depth,
        depth,
        labels,
        K,
        first_pose,
        PerceptionConfig(),
        K=K,
        world_from_camera=second_pose,
    )
    assert np.array_equal(from_grid.state, change.state)
    assert np.array_equal(from_grid.previous_label, change.previous_label)


def _supervoxels(labels: np.ndarray) -> Supervoxels:
    count = int(labels.max()) + 1
    return Supervoxels(
        labels=labels,
        centres=np.zeros((count, 3)),
        normals=np.tile([0.0, 0.0, -1.0], (count, 1)),
        colours=np.zeros((count, 3)),
        sizes=np.bincount(labels[labels >= 0], minlength=count),
        adjacency=np.zeros((0, 2), np.int64),
    )


def test_only_segments_that_stayed_anchor_supervoxels():
    # Four supervoxels of 100 px in a row. Previous segment 1 (supervoxels 0, 1) is unchanged;
    # segment 2 moved: supervoxel 2 still shows it unchanged, but most of its old pixels now
    # show what was behind it (supervoxel 3 revealed).
    supervoxel = np.repeat(np.arange(4), 100).reshape(20, 20).astype(np.int32)
    state = np.full(400, UNCHANGED, np.int8)
    previous = np.repeat([1, 1, 2, 2], 100).astype(np.int32)
    state[300:] = REVEALED
    state[290:300] = ARRIVED
    change = FrameChange(state.reshape(20, 20), previous.reshape(20, 20))
    result = supervoxel_anchors(_supervoxels(supervoxel), change, PerceptionConfig())
    assert result.anchor.tolist() == [1, 1, 0, 0]
    # Revealed pixels may belong to a static object; a moved segment's and arrived ones not.
    assert result.compatible_px.tolist() == [100, 100, 0, 100]
    assert result.incompatible_px.tolist() == [0, 0, 100, 0]


def test_anchors_split_merged_static_objects_and_join_split_ones():
    # Supervoxels 0-1 (previous object 1) and 2-3 (previous object 2) did not move. The
    # clustering put 1 and 2 together (part 1) and split object 1 (parts 0, 1). Supervoxel 4,
    # revealed, hangs on 3; supervoxel 5, a pushed object that arrived, hangs on 0.
    parts = np.array([0, 1, 1, 2, 2, 0])
    anchor = np.array([1, 1, 2, 2, 0, 0], np.int32)
    change = SupervoxelChange(anchor, np.array([0, 0, 0, 0, 50, 0]), np.array([0, 0, 0, 0, 0, 50]))
    pairs = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [0, 5]])
    weights = np.array([1.0, 0.001, 1.0, 1.0, 1.0])
    result = anchor_parts(parts, change, pairs, weights)
    assert result[0] == result[1] and result[2] == result[3] == result[4]
    assert result[1] != result[2]
    assert result[5] not in (result[0], result[2])
    # Without anchors nothing changes.
    none = SupervoxelChange(np.zeros(6, np.int32), np.zeros(6), np.zeros(6))
    assert anchor_parts(parts, none, pairs, weights).tolist() == parts.tolist()


def _wall(normal, offset, points) -> KnownPlane:
    return KnownPlane("wall", np.asarray(normal, float), offset, np.asarray(points, float), 0.018)


def test_walls_stay_and_a_new_wall_of_arrived_pixels_is_a_pushed_box():
    # Support z = 0; a wall x = 0.2 facing -x seen before; two new vertical planes, y = 0.1
    # (its pixels revealed: a wall a push uncovered) and y = -0.1 (its pixels arrived: the
    # face of a box pushed there).
    support = KnownPlane("support", np.array([0.0, 0.0, 1.0]), 0.0, np.zeros((0, 3)))
    z = np.linspace(0.03, 0.12, 10)
    s = np.linspace(-0.1, 0.1, 10)
    grid_s, grid_z = (g.ravel() for g in np.meshgrid(s, z))
    old = _wall([-1, 0, 0], 0.2, np.stack([np.full(100, 0.2), grid_s, grid_z], 1))
    revealed = _wall([0, -1, 0], 0.1, np.stack([grid_s, np.full(100, 0.1), grid_z], 1))
    pushed = _wall([0, 1, 0], 0.1, np.stack([grid_s, np.full(100, -0.1), grid_z], 1))
    above_points = np.concatenate([revealed.points, pushed.points])
    above = np.arange(200)
    state = np.concatenate([np.full(100, REVEALED), np.full(100, ARRIVED)]).astype(np.int8)
    config = PerceptionConfig()
    walls = consistent_walls(
        (old,), (revealed, pushed), support, above, above_points, state, config
    )
    assert walls == (revealed, old)
    # Found again (within 10 degrees and 2 cm), the new sighting replaces the old one.
    again = _wall([-0.999, 0.04, 0], 0.21, old.points)
    assert consistent_walls((old,), (again,), support, above, above_points, state, config) == (
        again,
    )
    assert same_plane(old, again, config) and not same_plane(old, revealed, config)


def test_a_new_wall_the_previous_frame_saw_as_an_object_is_that_object():
    # Two new vertical planes whose pixels did not change since the previous frame: y = 0.1
    # was unlabelled there (a wall the previous search missed: kept), y = -0.1 was an object
    # segment (a box pushed against the bin's wall in an earlier frame and still: not a wall).
    support = KnownPlane("support", np.array([0.0, 0.0, 1.0]), 0.0, np.zeros((0, 3)))
    z = np.linspace(0.03, 0.12, 10)
    s = np.linspace(-0.1, 0.1, 10)
    grid_s, grid_z = (g.ravel() for g in np.meshgrid(s, z))
    missed = _wall([0, -1, 0], 0.1, np.stack([grid_s, np.full(100, 0.1), grid_z], 1))
    box_face = _wall([0, 1, 0], 0.1, np.stack([grid_s, np.full(100, -0.1), grid_z], 1))
    above_points = np.concatenate([missed.points, box_face.points])
    above = np.arange(200)
    state = np.full(200, UNCHANGED, dtype=np.int8)
    previous_label = np.concatenate([np.zeros(100), np.full(100, 3)]).astype(np.int32)
    config = PerceptionConfig()
    found = (missed, box_face)
    args = (support, above, above_points, state, config)
    assert consistent_walls((), found, *args, previous_label) == (missed,)
    assert consistent_walls((), found, *args) == found  # without the previous labels
    # Half of the face an object before: still at most the share allowed, a wall.
    previous_label[150:] = 0
    assert consistent_walls((), found, *args, previous_label) == found


def test_a_frame_keeps_the_grouping_of_objects_that_did_not_move():
    from dataclasses import replace

    from ipr_shapes.perception.segmentation import segment_frame
    from tests.test_segmentation import box, camera, render, segment_of_point

    pose = camera()
    left, right = box(-0.1, 0.0, (0.08, 0.08, 0.08)), box(0.1, 0.0, (0.08, 0.08, 0.06))
    first = render(pose, boxes=[left, right], seed=1)
    before = segment_frame(first)
    assert len(before.segment_ids) == 2
    # A previous segmentation that grouped the two boxes as one object (labels only matter).
    merged = replace(before, labels=np.where(before.labels > 0, 1, 0).astype(np.int32))
    still = render(pose, boxes=[left, right], seed=2)
    fresh = segment_frame(still)
    kept = segment_frame(still, previous=(first, merged))
    points = ([-0.1, 0.0, 0.08], [0.1, 0.0, 0.06])
    fresh_ids = [segment_of_point(still, fresh.labels, p) for p in points]
    kept_ids = [segment_of_point(still, kept.labels, p) for p in points]
    assert fresh_ids[0] != fresh_ids[1] and kept_ids[0] == kept_ids[1] > 0
    assert kept.segment_ids == [1]
    # When the right box was pushed 10 cm, the merged segment did not stay: fresh grouping.
    pushed = render(pose, boxes=[left, box(0.1, 0.1, (0.08, 0.08, 0.06))], seed=2)
    moved = segment_frame(pushed, previous=(first, merged))
    moved_ids = [
        segment_of_point(pushed, moved.labels, p) for p in ([-0.1, 0, 0.08], [0.1, 0.1, 0.06])
    ]
    assert moved_ids[0] != moved_ids[1] and min(moved_ids) > 0
    off = PerceptionConfig(temporal=TemporalConfig(anchoring=False))
    assert segment_frame(still, previous=(first, merged), config=off).segment_ids == [1, 2]
