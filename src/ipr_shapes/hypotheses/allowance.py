"""Seen-free space an object's own measured surface excuses (issue 28, real sensors).

The unary constraint forbids a hypothesis more than a small share of voxels in space the camera
saw empty. That share stands for depth noise, but a real sensor's depth is also smoothed over
several pixels: near an object-support junction and at silhouettes it reads behind the true
surface (7-35 mm on the lab frames' cracker box). A convex candidate built on the observed
facets then stands in front of the measured surface there, in seen-free space, and on the real
lab frames every candidate of 27 objects failed (docs/experiments/
2026-11-27-real-frames-infeasible-candidates.md).

The object's own points tell how far its measured surface departs from a convex solid: a rigid
convex object measured exactly has every visible point on the boundary of the points' convex
hull, so the depth of the points inside that hull is the measurement's error (plus the object's
own concavity). The *allowance* of an object is a high quantile of that depth (metres); seen-free
voxels whose centre lies within the allowance of one of the object's observed points are
*excused*: they do not count against its hypotheses. The concavity part is why the excusal is
a second check only, for an object none of whose hypotheses passes without it
(``ipr_shapes.hypotheses.generate``): given to every object it admitted concave objects'
candidates on generated scenes and lost there (docs/experiments/2026-11-27-surface-allowance.md).
The allowance is 2 mm on generated scenes (median over objects; the simulated sensor adds axial
noise, not blur) and 3-31 mm for the real lab frames' objects that had no feasible candidate.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ipr_shapes import voxels
from ipr_shapes.perception.free_space import FREE, SeenSpace

#: Voxels examined at most per object (the allowance's box around its points): beyond this the
#: object is too large for the search and gets no allowance (a 1 m box at 5 mm is 8 million).
MAX_SEARCH_VOXELS = 4_000_000


def surface_allowance(
    points: np.ndarray, quantile: float, hull_points: np.ndarray | None = None
) -> float:
    """The ``quantile`` (0-1) of the depth (m, >= 0) of ``points`` (N, 3) inside the convex hull of
    ``hull_points`` (default ``points``; pass the hull's vertices when known, the same hull):
    how far the measured surface lies behind the convex solid it bounds. 0 for fewer than 4
    points or a flat set."""
    points = np.asarray(points, float).reshape(-1, 3)
    hull_points = points if hull_points is None else np.asarray(hull_points, float)
    if len(points) < 4 or len(hull_points) < 4:
        return 0.0
    try:
        planes = ConvexHull(hull_points).equations
    except (QhullError, ValueError):
        return 0.0
    # Outward unit normals: a point's depth inside is its smallest distance to a face plane.
    depth = -(points @ planes[:, :3].T + planes[:, 3]).max(axis=1)
    return float(max(np.quantile(depth, quantile), 0.0))


def excused_keys(
    points: np.ndarray, space: SeenSpace | None, pitch_m: float, allowance_m: float
) -> np.ndarray:
    """Sorted ``ipr_shapes.voxels`` keys (at ``pitch_m``) of the voxels ``space`` holds FREE
    whose centre lies within ``allowance_m`` of one of ``points`` (N, 3), world frame, metres.
    Empty without a space, without points or with no allowance."""
    points = np.asarray(points, float).reshape(-1, 3)
    if space is None or allowance_m <= 0 or len(points) == 0:
        return voxels.EMPTY.copy()
    low = np.floor((points.min(axis=0) - allowance_m) / pitch_m).astype(np.int64)
    high = np.floor((points.max(axis=0) + allowance_m) / pitch_m).astype(np.int64)
    shape = high - low + 1
    if int(np.prod(shape)) > MAX_SEARCH_VOXELS:
        return voxels.EMPTY.copy()
    axes = [np.arange(low[i], high[i] + 1) for i in range(3)]
    indices = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    centres = (indices + 0.5) * pitch_m
    free = space.state_at(centres) == FREE
    if not free.any():
        return voxels.EMPTY.copy()
    indices, centres = indices[free], centres[free]
    distance, _ = cKDTree(points).query(centres, distance_upper_bound=allowance_m)
    return np.unique(voxels.pack(indices[distance <= allowance_m]))
