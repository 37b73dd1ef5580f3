"""Segments cut along a concave crease inside their 3D convex hull (issue 27: flush contacts).

Two convex objects meeting flush (a bottle lying on a block, a box leaning on a box) can be
one segment: their surfaces run on into each other without a depth step, so the occluding
contour split (``contours.py``) has nothing to cut at, and the few edges across the crease
that the convexity graph takes for convex keep the spectral clustering from cutting there. In
3D the difference is plain: a convex object's visible surface lies on the convex hull of its
points (up to the noise and the supervoxels' curvature), while the crease where two convex
surfaces meet lies inside the hull of the union, the deeper the larger the objects and the
sharper the crease.

The cut: the supervoxels of the segment deeper inside the hull than
``segmentation.crease_cut_depth_m`` are taken out (the crease and its neighbourhood); when
the rest falls into exactly two large parts, each part gets back the crease supervoxels that
a flood from it in order of increasing depth reaches first (the crease runs along the
deepest line), and the segment is split in two. An open container's inside is as deep inside
its hull, but taking it out leaves the rim and the outer wall in one piece (a ring); where the
ring is broken (an occluder in front of it), one part lies within the other's footprint on
the support (the containers' rule, ``contours._one_within_other``), and the cut is refused.

docs/experiments/2026-11-27-flush-contacts.md has the measurements.
"""

from __future__ import annotations

import heapq

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.contours import _one_within_other
from ipr_shapes.perception.types import KnownPlane, Supervoxels

#: Pixels of a segment used for its hull: every ``_STRIDE``-th row and column of the image
#: (together with the supervoxel centres), at most ``_MAX_POINTS`` of them (an even subset).
_STRIDE = 3
_MAX_POINTS = 400
_SIDES = np.array([0, 1])
#: The 13 directions of a cube's face normals, edge and corner diagonals (``_slab_depth_bound``).
_DIRECTIONS = np.array(
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1], [0, 1, 1]]
    + [[0, 1, -1], [1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]],
    dtype=np.float64,
)
_DIRECTIONS /= np.linalg.norm(_DIRECTIONS, axis=1, keepdims=True)
#: Ratio of successive cut depths (``_cut_levels``).
_LEVEL_STEP = 0.8


def hull_depths(points: np.ndarray, queries: np.ndarray) -> np.ndarray | None:
    """(Q,) depth (m) of each query point inside the convex hull of ``points`` (N, 3), world;
    0 on the hull, negative outside; None when the points span no volume (a flat face)."""
    try:
        equations = ConvexHull(points).equations
    except (QhullError, ValueError):
        return None
    return -(queries @ equations[:, :3].T + equations[:, 3]).max(axis=1)


def split_at_creases(
    segment_of_supervoxel: np.ndarray,
    supervoxels: Supervoxels,
    points: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
) -> np.ndarray:
    """(M,) int32 segments with each segment that is two convex surfaces meeting at a concave
    crease cut along it (module docstring).

    ``segment_of_supervoxel`` (M,) int, 0 = none; ``supervoxels`` their pixels, sizes,
    centres (world) and adjacency; ``points`` (H, W, 3) world (m); ``support`` the support
    plane (footprints for the container test). A segment of at least twice
    ``segmentation.crease_split_px`` pixels whose supervoxel centres reach
    ``segmentation.crease_split_depth_m`` inside the convex hull of its points (sampled
    pixels and the centres) is split when the supervoxels less deep than a cut depth
    (``_cut_levels``: from 0.8 ``crease_split_depth_m`` down to
    ``segmentation.crease_cut_depth_m``, the first that does) form exactly two connected
    parts (supervoxel adjacency within the segment) of at least
    ``segmentation.crease_split_px`` pixels each, and neither part lies within the other's
    footprint. The second part and the crease
    supervoxels flooded from it take the next free label; the others keep theirs.
    """
    seg = config.segmentation
    min_depth = float(seg.crease_split_depth_m)
    count = len(segment_of_supervoxel)
    if min_depth <= 0 or count == 0:
        return segment_of_supervoxel
    segment_of_supervoxel = np.asarray(segment_of_supervoxel)
    n_segments = int(segment_of_supervoxel.max()) + 1
    if n_segments <= 1:
        return segment_of_supervoxel
    min_px = int(seg.crease_split_px)
    levels = _cut_levels(min_depth, float(seg.crease_cut_depth_m))
    pixels = np.bincount(segment_of_supervoxel, weights=supervoxels.sizes, minlength=n_segments)
    nodes_of = np.bincount(segment_of_supervoxel, minlength=n_segments)
    candidate = (pixels >= 2 * min_px) & (nodes_of >= 4)
    candidate[0] = False
    if not candidate.any():
        return segment_of_supervoxel
    # Sampled pixels, grouped by segment.
    width = supervoxels.labels.shape[1]
    grid = supervoxels.labels[::_STRIDE, ::_STRIDE]
    rows, cols = np.nonzero(grid >= 0)
    sample_segment = segment_of_supervoxel[grid[rows, cols]]
    chosen = candidate[sample_segment]
    flat = (rows[chosen] * _STRIDE) * width + cols[chosen] * _STRIDE
    sample_segment = sample_segment[chosen]
    order = np.argsort(sample_segment, kind="stable")
    flat, sample_segment = flat[order], sample_segment[order]
    bounds = np.searchsorted(sample_segment, np.arange(n_segments + 1))
    world = points.reshape(-1, 3)
    pairs = supervoxels.adjacency
    same = (
        segment_of_supervoxel[pairs[:, 0]] == segment_of_supervoxel[pairs[:, 1]]
        if len(pairs)
        else np.zeros(0, dtype=bool)
    )
    result = segment_of_supervoxel.astype(np.int32).copy()
    next_label = n_segments
    for s in np.flatnonzero(candidate):
        nodes = np.flatnonzero(segment_of_supervoxel == s)
        centres = supervoxels.centres[nodes]
        sampled = flat[bounds[s] : bounds[s + 1]]
        sampled = sampled[:: -(-sampled.size // _MAX_POINTS) or 1]
        cloud = np.vstack([world[sampled], centres])
        if _slab_depth_bound(cloud, centres) < min_depth:
            continue
        depth = hull_depths(cloud, centres)
        if depth is None or depth.max() < min_depth:
            continue
        edges = pairs[same & (segment_of_supervoxel[pairs[:, 0]] == s)]
        side = None
        for level in levels:
            side = _crease_sides(nodes, depth, edges, supervoxels.sizes, level, min_px)
            if side is not None:
                break
        if side is None:
            continue
        # The container test on the sampled pixels (an even subset, as the test takes).
        sample_side = np.full(count + 1, -1, dtype=np.int64)
        sample_side[nodes] = side
        sample_part = sample_side[supervoxels.labels.reshape(-1)[sampled]]
        if _one_within_other(sample_part, _SIDES, world[sampled], support, config):
            continue
        result[nodes[side == 1]] = next_label
        next_label += 1
    return result


def _slab_depth_bound(cloud: np.ndarray, queries: np.ndarray) -> float:
    """An upper bound (m) of the deepest of ``queries`` (Q, 3) inside the convex hull of
    ``cloud`` (N, 3) (world, m), without the hull: the hull lies within the slab between the
    cloud's extremes along any direction, so a point is no deeper inside it than its distance
    to the nearer side of any such slab (13 fixed directions and the cloud's 3 principal
    axes). Flat and thin segments, most of them, need no hull (a hull costs about 0.4 ms)."""
    spread = cloud - cloud.mean(axis=0)
    directions = np.vstack([_DIRECTIONS, np.linalg.eigh(spread.T @ spread)[1].T])
    along = cloud @ directions.T
    at = queries @ directions.T
    room = np.minimum(along.max(axis=0) - at, at - along.min(axis=0))
    return float(room.min(axis=1).max())


def _cut_levels(split_depth: float, floor: float) -> list[float]:
    """Depths (m) at which the crease is taken out, deepest first: ``split_depth`` times 0.8,
    0.8^2, ... while above ``floor``, then ``floor``. The first level that leaves two large
    parts takes out the least of the segment (the crease itself, not its flanks); a single
    fixed level either left a 2 mm bridge of supervoxel centres across a crease (too deep) or
    cut into the noise of curved surfaces (too shallow)."""
    levels = []
    level = split_depth * _LEVEL_STEP
    while level > floor:
        levels.append(level)
        level *= _LEVEL_STEP
    levels.append(floor)
    return levels


def _crease_sides(
    nodes: np.ndarray,
    depth: np.ndarray,
    edges: np.ndarray,
    sizes: np.ndarray,
    cut_depth: float,
    min_px: int,
) -> np.ndarray | None:
    """(n,) side 0 or 1 of each of a segment's supervoxels ``nodes`` (n,), or None when the
    supervoxels less deep than ``cut_depth`` (m; ``depth`` (n,)) do not form exactly two
    parts of at least ``min_px`` pixels under the segment's adjacency ``edges`` (E, 2)
    (supervoxel ids), or when those two are not joined through the deeper ones. The deeper supervoxels go, in order of increasing depth, to the side of
    the neighbour that reaches them first (a flood from both parts; the crease, deepest, is
    reached last); any the flood never reaches stay with side 0."""
    n = len(nodes)
    local = np.searchsorted(nodes, edges)  # nodes sorted (flatnonzero)
    a, b = local[:, 0], local[:, 1]
    shallow = depth < cut_depth
    kept = shallow[a] & shallow[b]
    graph = coo_matrix((np.ones(int(kept.sum())), (a[kept], b[kept])), shape=(n, n))
    _, part = connected_components(graph, directed=False)
    part = np.where(shallow, part, -1)
    part_px = np.bincount(part[shallow], weights=sizes[nodes[shallow]])
    large = np.flatnonzero(part_px >= min_px)
    if len(large) != 2:
        return None
    # The two parts must meet through the crease: pieces of a segment that do not touch at all
    # (an object seen on both sides of an occluder, objects the previous frame's grouping
    # keeps together) are not cut here.
    _, whole = connected_components(
        coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)), directed=False
    )
    first, second = (np.flatnonzero(part == p)[0] for p in large)
    if whole[first] != whole[second]:
        return None
    side = np.full(n, -1, dtype=np.int64)
    side[part == large[0]] = 0
    side[part == large[1]] = 1
    neighbours: list[list[int]] = [[] for _ in range(n)]
    for i, j in zip(a.tolist(), b.tolist(), strict=True):
        neighbours[i].append(j)
        neighbours[j].append(i)
    heap: list[tuple[float, int, int]] = []
    for v in np.flatnonzero(side >= 0).tolist():
        for u in neighbours[v]:
            if side[u] < 0:
                heapq.heappush(heap, (float(depth[u]), u, int(side[v])))
    while heap:
        _, u, s = heapq.heappop(heap)
        if side[u] >= 0:
            continue
        side[u] = s
        for w in neighbours[u]:
            if side[w] < 0:
                heapq.heappush(heap, (float(depth[w]), w, s))
    side[side < 0] = 0
    return side
