"""Pixels of the robot and of the pusher, removed before segmentation (paper Sec. III-A).

The paper removes the robot's arm and hand with its model and forward kinematics. Scenes give
that removal as ``mask_robot/`` images (``Frame.robot_mask``); the pusher is known as a capsule
(``Pusher``) moving along each ``Push``. By the scene contract the pusher is withdrawn before a
frame is captured, but a tool may leave it in view: where it stood when the frame was taken (the
start of the push that follows the frame, the end of the push that precedes it), the pixels whose
3D point lies inside the capsule are removed as well.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.scene import Frame, Push, Pusher


def robot_pixels(
    frame: Frame,
    pushes: Sequence[Push] = (),
    pusher: Pusher | None = None,
    config: PerceptionConfig = PerceptionConfig(),  # noqa: B008 (frozen)
    *,
    points_world: np.ndarray | None = None,
) -> np.ndarray:
    """(H, W) bool: pixels of ``frame`` that show the robot or the pusher.

    A pixel is the robot's when ``frame.robot_mask`` says so, or when its 3D point (valid depth
    only) lies within ``pusher.radius_m + config.robot.pusher_margin_m`` of the pusher's axis
    segment at the start of a push whose ``before_frame`` is this frame or at the end of a push
    whose ``after_frame`` is this frame. ``points_world`` (H, W, 3), when given, saves
    recomputing ``frame.points_world()``.
    """
    height, width = frame.shape
    mask = (
        np.zeros((height, width), dtype=bool)
        if frame.robot_mask is None
        else np.asarray(frame.robot_mask, dtype=bool).copy()
    )
    if pusher is None:
        return mask
    centres = [p.start_m for p in pushes if p.before_frame == frame.index]
    centres += [p.end_m for p in pushes if p.after_frame == frame.index]
    if not centres:
        return mask
    valid = frame.depth_m.reshape(-1) > 0
    if not valid.any():
        return mask
    if points_world is None:
        points_world = frame.points_world()
    points = points_world.reshape(-1, 3)
    axis = np.asarray(pusher.axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    half = max(pusher.length_m / 2.0 - pusher.radius_m, 0.0)  # centre to the caps' centres
    reach = pusher.radius_m + config.robot.pusher_margin_m
    inside = np.zeros(valid.size, dtype=bool)
    for centre in centres:
        centre = np.asarray(centre, dtype=np.float64)
        a, b = centre - half * axis, centre + half * axis
        # Cheap bounding-box test first: only points near the capsule need the exact distance.
        # One coordinate at a time, on the strided column of the whole image first and then
        # only on the survivors: no (N, 3) gather or temporaries of the ~300000 valid points.
        low, high = np.minimum(a, b) - reach, np.maximum(a, b) + reach
        x = points[:, 0]
        candidates = np.flatnonzero(valid & (x >= low[0]) & (x <= high[0]))
        for coordinate in (1, 2):
            values = points[candidates, coordinate]
            candidates = candidates[(values >= low[coordinate]) & (values <= high[coordinate])]
        if candidates.size == 0:
            continue
        offsets = points[candidates] - a
        t = np.clip(offsets @ axis, 0.0, 2.0 * half)
        distance = np.linalg.norm(offsets - t[:, None] * axis, axis=1)
        inside[candidates[distance <= reach]] = True
    mask.reshape(-1)[inside] = True
    return mask
