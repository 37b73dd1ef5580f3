"""One segment for an object that a nearer object cuts in two in the image (beyond the paper).

A bottle lying across a box, a can in front of a sugar box: the occluder hides a band across
the object behind it, whose two visible pieces do not touch in the image. The supervoxel graph
has no edge between them, so the segmentation gives each piece its own segment, and the label
images (the segmentation benchmark, the tracker) count the object as split.
``ipr_shapes.perception.occlusion`` joins such pieces later, for inference only, from frame 0's
free space; this step joins them in every frame's label image, from that frame's depth alone.

Two segments ``a`` and ``b`` that do not touch in the image are joined when all of these hold
(``OccluderSplitsConfig``):

- **a nearer object lies between them**: both share a border with one segment ``c`` that is
  nearer than each of them across that border (an occluding contour), and the image lines
  between their nearest border pixels (``pairs`` of the pairs within ``band_px`` of the
  nearest, at most ``max_gap_px`` long) run over pixels with depth at least ``min_occluded`` of
  which are nearer than the depth interpolated along the line between its two ends by
  ``step_m``, and at most ``max_seen_beyond`` of which are farther than that by ``step_m`` or
  unlabelled (support, walls, background: the camera sees past the gap, which is then free
  space between two objects); pixels without a reading count for neither;
- **the hidden gap is short**: the median 3D distance between the lines' two ends is at most
  ``max_gap_m`` (an occluder hides a few centimetres of what lies behind it);
- **the surfaces continue each other**: locally, each line's end lies within ``max_step_m``
  (median over the lines) of the plane fitted to the other piece's points within
  ``normal_radius_m`` of the other end (one surface runs on under the occluder; two boxes of
  different heights meet in a step); and globally, one quadric surface (a height field of
  degree 2 over the union's principal plane) fits the union with an RMS residual at most
  ``max_joint_rms_m`` and at most ``max_rms_increase_m`` above the rougher piece's own fit;
- **they look alike**: the Bhattacharyya distance between their colour histograms (the
  tracker's bins, ``tracking.COLOUR_BINS``) is at most ``max_colour``;
- **one object's size**: the union's extent along each world axis is at most
  ``max_extent_m``.

Pairs are joined best first (smallest joint residual), each segment at most once per frame: a
chain of joins would compare pieces with unions the tests never saw. The joined segment keeps
the lower label. The choices and their measurements: docs/experiments/2026-11-27-occluder-splits.md.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ipr_shapes.perception.config import OccluderSplitsConfig
from ipr_shapes.perception.tracking import COLOUR_BINS, _colour_codes

#: Points of a piece used for its quadric fit at most (evenly strided): the fit is a 6-column
#: least-squares problem, whose residual is as well estimated from a few thousand points.
_FIT_POINTS = 2000


def quadric_rms(points: np.ndarray) -> float:
    """RMS residual (m) of the least-squares quadric height field z = f(x, y) of degree 2 fitted
    to (N, 3) points in their own principal frame (x, y along the two largest principal axes, z
    along the smallest): the roughness of the surface the points lie on, 0 for a plane, a
    cylinder patch or a sphere cap seen from one side. Fewer than 6 points: 0."""
    if len(points) < 6:
        return 0.0
    centred = points - points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    local = centred @ axes.T
    x, y, z = local[:, 0], local[:, 1], local[:, 2]
    design = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    coefficients, *_ = np.linalg.lstsq(design, z, rcond=None)
    return float(np.sqrt(np.mean((z - design @ coefficients) ** 2)))


def _borders(labels: np.ndarray, depth_m: np.ndarray, step_m: float):
    """Pairs of labels that touch (4-neighbours, both > 0), and for each label ``a`` the labels
    nearer than it by more than ``step_m`` across a shared border (its occluders).

    Returns (set of (low, high) label pairs that touch, dict label -> set of occluder labels).
    """
    touching: set[tuple[int, int]] = set()
    occluders: dict[int, set[int]] = {}
    base = int(labels.max()) + 1  # (x, y) label pairs coded as x * base + y
    for first, second, depth_first, depth_second in (
        (labels[:, :-1], labels[:, 1:], depth_m[:, :-1], depth_m[:, 1:]),
        (labels[:-1], labels[1:], depth_m[:-1], depth_m[1:]),
    ):
        differ = (first != second) & (first > 0) & (second > 0)
        if not differ.any():
            continue
        a, b = first[differ].astype(np.int64), second[differ].astype(np.int64)
        da, db = depth_first[differ], depth_second[differ]
        for code in np.unique(np.minimum(a, b) * base + np.maximum(a, b)).tolist():
            touching.add(divmod(code, base))
        valid = (da > 0) & (db > 0)
        # Each direction: the second label nearer than the first occludes it.
        for behind, front, d_behind, d_front in ((a, b, da, db), (b, a, db, da)):
            nearer = valid & (d_front < d_behind - step_m)
            for code in np.unique(behind[nearer] * base + front[nearer]).tolist():
                x, y = divmod(code, base)
                occluders.setdefault(x, set()).add(y)
    return touching, occluders


def _path_evidence(
    a: int,
    b: int,
    labels: np.ndarray,
    depth_m: np.ndarray,
    points: np.ndarray,
    edges: dict[int, np.ndarray],
    config: OccluderSplitsConfig,
) -> tuple[float, float, np.ndarray] | None:
    """(occluded share, seen-beyond share, (L, 2, 3) world points (m) of the ends on ``a`` and
    on ``b``) of the L image lines
    between segments ``a`` and ``b`` (module doc), or None when they are farther apart than
    ``max_gap_px`` or no line has pixels with depth between them (the shares are of those). ``edges``: each segment's (N, 2) row,
    column of its pixels with depth on its border (a 4-neighbour has another label): the
    nearest pixels of two segments that do not touch are border pixels."""
    first, second = edges[a], edges[b]
    if len(first) == 0 or len(second) == 0:
        return None
    tree = cKDTree(first)
    distance, nearest = tree.query(second, k=1)
    gap = float(distance.min())
    if gap > config.max_gap_px:
        return None
    order = np.argsort(distance, kind="stable")
    order = order[distance[order] <= gap + config.band_px]
    if len(order) > config.pairs:  # spread over the band, not the closest few pixels only
        order = order[np.linspace(0, len(order) - 1, config.pairs).round().astype(int)]
    # All L lines at once: line i has steps[i] pixels from its end on a to its end on b.
    stop, begin = second[order], first[nearest[order]]
    steps = np.ceil(distance[order]).astype(np.int64) + 1
    line = np.repeat(np.arange(len(order)), steps)
    position = np.arange(len(line)) - np.repeat(np.cumsum(steps) - steps, steps)
    weight = position / np.maximum(steps[line] - 1, 1)
    rows = np.round(begin[line, 0] + (stop[line, 0] - begin[line, 0]) * weight).astype(np.int64)
    cols = np.round(begin[line, 1] + (stop[line, 1] - begin[line, 1]) * weight).astype(np.int64)
    near_depth = depth_m[begin[:, 0], begin[:, 1]][line]
    far_depth = depth_m[stop[:, 0], stop[:, 1]][line]
    expected = near_depth * (1 - weight) + far_depth * weight
    on_line = labels[rows, cols]
    inner = (on_line != a) & (on_line != b)
    depth = depth_m[rows, cols]
    valid = depth > 0
    nearer = inner & valid & (depth < expected - config.step_m)
    farther = inner & valid & (depth > expected + config.step_m)
    unlabelled = inner & valid & (on_line == 0) & ~nearer
    # Pixels without a reading (often along the occluder's edge) tell nothing either way.
    inner_total = int((inner & valid).sum())
    if inner_total == 0:
        return None
    ends = np.stack(
        [points[begin[:, 0], begin[:, 1]], points[stop[:, 0], stop[:, 1]]], axis=1
    ).astype(np.float64)
    return (
        int(nearer.sum()) / inner_total,
        int((farther | unlabelled).sum()) / inner_total,
        ends,
    )


def _normals_at(
    where: np.ndarray, points: np.ndarray, tree: cKDTree, radius_m: float
) -> np.ndarray:
    """(L, 3) unit normals of the surface of (N, 3) ``points`` at (L, 3) points ``where``: the
    least principal axis of the points within ``radius_m`` (zeros where fewer than 5)."""
    normals = np.zeros((len(where), 3))
    for row, near in enumerate(tree.query_ball_point(where, radius_m)):
        if len(near) >= 5:
            local = points[near] - points[near].mean(axis=0)
            normals[row] = np.linalg.svd(local, full_matrices=False)[2][2]
    return normals


def _step(
    ends: np.ndarray,
    piece_points: dict[int, np.ndarray],
    trees: dict[int, cKDTree],
    a: int,
    b: int,
    radius_m: float,
) -> float:
    """Median over the lines of how far (m) each end lies off the other end's local tangent
    plane (the larger of the two): 0 where one surface runs on under the occluder, the height
    of the step between two surfaces that do not continue each other. Ends without a normal
    count as no step; with none at all: 0."""
    normals_a = _normals_at(ends[:, 0], piece_points[a], trees[a], radius_m)
    normals_b = _normals_at(ends[:, 1], piece_points[b], trees[b], radius_m)
    offsets = ends[:, 1] - ends[:, 0]
    step = np.maximum(
        np.abs(np.einsum("ij,ij->i", normals_a, offsets)),
        np.abs(np.einsum("ij,ij->i", normals_b, offsets)),
    )
    return float(np.median(step)) if len(step) else 0.0


def join_occluder_splits(
    labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    rgb: np.ndarray,
    config: OccluderSplitsConfig | None = None,
) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """Join the two pieces of objects cut in two by a nearer object (module doc).

    Args:
        labels: (H, W) int32 segment labels (0 = none).
        segment_of_supervoxel: (S,) int32 segment of each supervoxel, consistent with labels.
        points: (H, W, 3) world points (m); depth_m: (H, W) depth (m, 0 = no reading);
        rgb: (H, W, 3) uint8 colours.
        config: settings (defaults: ``OccluderSplitsConfig()``, off).

    Returns:
        The labels and supervoxel segments with every joined piece under its partner's
        (lower) label, and the (kept, joined) label pairs; the inputs themselves when nothing
        is joined.
    """
    config = config or OccluderSplitsConfig()
    if not config.enabled or labels.max() < 2:
        return labels, segment_of_supervoxel, []
    touching, occluders = _borders(labels, depth_m, config.step_m)
    behind = sorted(k for k, v in occluders.items() if v)
    if len(behind) < 2:
        return labels, segment_of_supervoxel, []
    valid = depth_m > 0
    # Candidate pairs: no shared border, one occluder in common.
    candidates = [
        (a, b)
        for i, a in enumerate(behind)
        for b in behind[i + 1 :]
        if (a, b) not in touching and occluders[a] & occluders[b]
    ]
    if not candidates:
        return labels, segment_of_supervoxel, []
    involved = np.array(sorted({k for pair in candidates for k in pair}))
    # Every involved segment's pixels in one pass (a frame has a dozen segments).
    flat = labels.reshape(-1)
    chosen = np.flatnonzero(np.isin(flat, involved))
    chosen = chosen[np.argsort(flat[chosen], kind="stable")]
    bounds = np.searchsorted(flat[chosen], np.append(involved, involved[-1] + 1))
    border = np.zeros(labels.shape, dtype=bool)
    border[:, :-1] |= labels[:, :-1] != labels[:, 1:]
    border[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    border[:-1] |= labels[:-1] != labels[1:]
    border[1:] |= labels[1:] != labels[:-1]
    flat_valid, flat_border = valid.reshape(-1), border.reshape(-1)
    flat_points, flat_rgb = points.reshape(-1, 3), rgb.reshape(-1, 3)
    width = labels.shape[1]
    edges, piece_points, histograms, roughness, sizes, trees = {}, {}, {}, {}, {}, {}
    for number, k in enumerate(involved.tolist()):
        own = chosen[bounds[number] : bounds[number + 1]]
        codes = _colour_codes(flat_rgb[own])
        counts = np.bincount(codes, minlength=COLOUR_BINS**3).astype(np.float64)
        histograms[k] = counts / max(counts.sum(), 1.0)
        own = own[flat_valid[own]]
        sizes[k] = len(own)
        on_edge = own[flat_border[own]]
        edges[k] = np.stack([on_edge // width, on_edge % width], axis=1)
        piece_points[k] = flat_points[own[:: max(len(own) // _FIT_POINTS, 1)]]
    passed = []
    for a, b in candidates:
        if min(sizes[a], sizes[b]) < config.min_piece_px:
            continue
        union = np.concatenate([piece_points[a], piece_points[b]])
        if np.any(np.ptp(union, axis=0) > config.max_extent_m):
            continue
        evidence = _path_evidence(a, b, labels, depth_m, points, edges, config)
        if evidence is None:
            continue
        occluded, beyond, ends = evidence
        if occluded < config.min_occluded or beyond > config.max_seen_beyond:
            continue
        if np.median(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)) > config.max_gap_m:
            continue
        for k in (a, b):
            if k not in trees:
                trees[k] = cKDTree(piece_points[k])
        if _step(ends, piece_points, trees, a, b, config.normal_radius_m) > config.max_step_m:
            continue
        for k in (a, b):
            if k not in roughness:
                roughness[k] = quadric_rms(piece_points[k])
        joint = quadric_rms(union)
        if joint > config.max_joint_rms_m:
            continue
        if joint - max(roughness[a], roughness[b]) > config.max_rms_increase_m:
            continue
        affinity = float(np.sqrt(histograms[a]) @ np.sqrt(histograms[b]))
        if np.sqrt(max(1.0 - affinity, 0.0)) > config.max_colour:
            continue
        passed.append((joint, a, b))
    if not passed:
        return labels, segment_of_supervoxel, []
    used: set[int] = set()
    joins = []
    lookup = np.arange(int(labels.max()) + 1, dtype=labels.dtype)
    for _, a, b in sorted(passed):
        if a in used or b in used:
            continue
        used.update((a, b))
        lookup[b] = a
        joins.append((a, b))
    relabelled = lookup[labels]
    segments = np.where(
        segment_of_supervoxel > 0,
        lookup[np.clip(segment_of_supervoxel, 0, len(lookup) - 1)],
        segment_of_supervoxel,
    ).astype(segment_of_supervoxel.dtype)
    return relabelled, segments, joins
