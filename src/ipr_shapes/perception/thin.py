"""Thin cylinders (markers, pens, handles) joined when their pieces lie on one cylinder.

A cylinder of radius r shows about pi r of its circumference to the camera. When that is no
more than two supervoxel seeds (``supervoxels.seed_size_m``, 2 cm: r up to 12.5 mm),
neighbouring supervoxels lie along its axis, and the line between their centres runs along
the crease of their normals: LCCP's
singular configuration, in which the centres and normals cannot tell a convex surface from two
objects touching edge-on, so the graph weakens those edges (``segmentation.edge_weights``) and
the spectral clustering cuts a marker where its cap, print and body meet (their supervoxels
follow the colours). What the pieces of one thin cylinder share is the cylinder: two touching
segments are joined when the points of both lie on one cylinder of radius at most
``segmentation.thin_radius_m``, with a radial residual (RMS) of at most
``segmentation.thin_rms_m``, the depth noise. Two objects that touch make no such cylinder
together (a box and a bottle, two markers side by side), and colour is not asked (a marker's
cap and body differ). Two thin objects lying end to end on one axis would be joined; one view
cannot tell them from one.
"""

from __future__ import annotations

import numpy as np

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.fragments import merge_counts, relabelled_by_root, segment_borders
from ipr_shapes.perception.types import Supervoxels

#: Points of a segment used for the cylinder fit (an even subset).
_MAX_POINTS = 300


def cylinder_fit(points: np.ndarray, viewpoint: np.ndarray) -> tuple[float, float]:
    """(radius, RMS radial residual), metres, of the convex cylinder through (N, 3) points
    seen from ``viewpoint`` (3,), all in one frame ((inf, inf): none; ``_cylinder``)."""
    fitted = _cylinder(points, viewpoint)
    if fitted is None:
        return np.inf, np.inf
    radius, residual, _ = fitted
    return radius, float(np.sqrt(np.mean(residual**2)))


def _cylinder(
    points: np.ndarray, viewpoint: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray] | None:
    """The convex cylinder through (N, 3) points seen from ``viewpoint`` (3,): its radius (m),
    each point's radial residual (N,) and position along the axis (N,) (m), or None.

    The axis is the points' principal direction (a thin cylinder's pieces are longer along
    it than across); the cross-section is the least-squares (Kasa) circle of the points
    projected on the plane across it. The axis must lie behind the surface as seen from the
    viewpoint, by at least a quarter of the radius: the seen half of a cylinder is on average
    2/pi to pi/4 of the radius nearer than its axis (less where part of it is hidden), while a
    flat strip, which a small circle centred among its points fits with a residual of a third
    of its width, has that circle's centre among its points. None when no circle fits that
    way, or with fewer than 10 points.
    """
    if len(points) < 10:
        return None
    mean = points.mean(axis=0)
    centred = points - mean
    _, vectors = np.linalg.eigh(centred.T @ centred)
    across = centred @ vectors[:, :2]  # the two smaller principal directions
    design = np.column_stack([across, np.ones(len(across))])
    try:  # least squares by the normal equations: 3 unknowns, a few hundred points
        solution = np.linalg.solve(design.T @ design, design.T @ (across**2).sum(axis=1))
    except np.linalg.LinAlgError:
        return None
    centre = solution[:2] / 2.0
    squared = solution[2] + centre @ centre
    if not np.isfinite(squared) or squared <= 0:
        return None
    radius = float(np.sqrt(squared))
    axis_point = mean + vectors[:, :2] @ centre
    behind = np.linalg.norm(axis_point - viewpoint) - np.mean(
        np.linalg.norm(points - viewpoint, axis=1)
    )
    if behind < 0.25 * radius:
        return None
    residual = np.linalg.norm(across - centre, axis=1) - radius
    return radius, residual, centred @ vectors[:, 2]


def pieces_fit(first: np.ndarray, second: np.ndarray, viewpoint: np.ndarray) -> tuple[float, float]:
    """(radius, the larger of the two pieces' RMS radial residuals), metres, of one convex
    cylinder through two pieces' (N, 3) and (M, 3) points, or (inf, inf).

    Each piece must lie on it (a small piece beside a marker could hide in the joint RMS),
    and end to end with the other along its axis: the segmentation cuts a thin cylinder across
    (each supervoxel spans its width), so the pieces' axial extents (5th to 95th percentile)
    overlap by at most half of the shorter one, while an object lying beside a marker runs
    along it.
    """
    fitted = _cylinder(np.concatenate([first, second]), viewpoint)
    if fitted is None:
        return np.inf, np.inf
    radius, residual, along = fitted
    split = len(first)
    rms = max(
        float(np.sqrt(np.mean(residual[:split] ** 2))),
        float(np.sqrt(np.mean(residual[split:] ** 2))),
    )
    low_a, high_a = np.percentile(along[:split], [5, 95])
    low_b, high_b = np.percentile(along[split:], [5, 95])
    overlap = min(high_a, high_b) - max(low_a, low_b)
    if overlap > 0.5 * min(high_a - low_a, high_b - low_b):
        return np.inf, np.inf
    return radius, rms


def _moments(points: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """(count, mean (3,), scatter (3, 3)) of (N, 3) points."""
    mean = points.mean(axis=0)
    centred = points - mean
    return len(points), mean, centred.T @ centred


def _second_spread(moments: tuple[int, np.ndarray, np.ndarray]) -> float:
    """Standard deviation (m) of points along their second principal direction."""
    count, _, scatter = moments
    return float(np.sqrt(max(np.linalg.eigvalsh(scatter / count)[1], 0.0)))


def _union(first: tuple, second: tuple) -> tuple[int, np.ndarray, np.ndarray]:
    """The moments of two point sets together, from theirs."""
    (n_a, mean_a, scatter_a), (n_b, mean_b, scatter_b) = first, second
    offset = mean_b - mean_a
    count = n_a + n_b
    return (
        count,
        mean_a + offset * (n_b / count),
        scatter_a + scatter_b + np.outer(offset, offset) * (n_a * n_b / count),
    )


def join_thin_pieces(
    labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    K: np.ndarray,
    rgb: np.ndarray,
    supervoxels: Supervoxels,
    viewpoint: np.ndarray,
    config: PerceptionConfig,
    *,
    borders: tuple | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Join touching segments whose points lie on one thin cylinder (module doc).

    Pairs that touch (at least ``segmentation.thin_min_contact_px`` neighbouring pixel pairs
    whose world points are within ``segmentation.fragment_gap_m``) are joined best fit first,
    and a joined pair is fitted again with its other neighbours, so a marker cut in three
    joins in two steps. A joined segment takes the larger one's label; every other label is
    kept.

    Args:
        labels: (H, W) int segment labels, 0 = none; segment_of_supervoxel: (M,) the segment of
            each supervoxel (relabelled the same way).
        points: (H, W, 3) world points (m); depth_m: (H, W) depth (m), 0 = no reading;
        K: (3, 3) camera intrinsics (px); rgb: (H, W, 3) colours; supervoxels: the frame's
            supervoxels (``labels`` (H, W), -1 = none); viewpoint: (3,) the camera's position
            in the points' frame (m).
        borders: ``fragments.segment_borders`` of these labels with the fragments' gap, if
            already computed (``fragments.fragment_borders``; not modified).

    Returns:
        The relabelled (labels, segment_of_supervoxel); the inputs when nothing is joined.
    """
    seg = config.segmentation
    if seg.thin_radius_m <= 0 or labels.max() < 2:
        return labels, segment_of_supervoxel
    valid = depth_m.reshape(-1) > 0
    order, ids, starts = kernels.labelled_order(labels.reshape(-1), valid)
    flat_points = points.reshape(-1, 3)
    members = {
        int(s): flat_points[pixels[:: -(-len(pixels) // _MAX_POINTS)]]
        for s, pixels in zip(ids.tolist(), np.split(order, starts[1:]), strict=True)
    }
    # Only slender segments can be pieces of a thin cylinder: across its axis, the seen half
    # of a cylinder of radius r spreads with a standard deviation of r / sqrt(2) at most, so a
    # piece's second largest spread is either that or its length along the axis (a short
    # piece), which then is as short.
    limit = seg.thin_radius_m / np.sqrt(2.0) + seg.thin_rms_m
    moments = {s: _moments(p) for s, p in members.items() if len(p) >= 3}
    slender = {s for s, m in moments.items() if _second_spread(m) <= limit}
    if len(slender) < 2:
        return labels, segment_of_supervoxel
    n = int(labels.max()) + 1
    # Touching pixel pairs of every two segments, whatever their normals.
    if borders is None:
        borders = segment_borders(
            labels, points, depth_m, K, rgb, supervoxels, seg.fragment_gap_m, 180.0
        )
    area, touching = borders[0].copy(), borders[4].copy()
    outside = np.array([s not in slender for s in range(n)])
    touching[outside] = 0
    touching[:, outside] = 0
    fits: dict[tuple[int, int], tuple[float, float]] = {}

    def fit(a: int, b: int) -> tuple[float, float]:
        if (a, b) not in fits:
            if _second_spread(_union(moments[a], moments[b])) > limit:
                fits[a, b] = (np.inf, np.inf)  # together no longer slender
            else:
                fits[a, b] = pieces_fit(members[a], members[b], viewpoint)
        return fits[a, b]

    root = np.arange(n)
    while True:
        best = None
        for a, b in np.argwhere(np.triu(touching >= seg.thin_min_contact_px, k=1)):
            radius, rms = fit(int(a), int(b))
            fits_thin = radius <= seg.thin_radius_m and rms <= seg.thin_rms_m
            if fits_thin and (best is None or rms < best[0]):
                best = (rms, int(a), int(b))
        if best is None:
            break
        _, a, b = best
        keep, gone = (a, b) if area[a] >= area[b] else (b, a)
        root[root == gone] = keep
        area[keep] += area[gone]
        merge_counts(touching, gone, keep)
        joined = np.concatenate([members.pop(keep), members.pop(gone)])
        members[keep] = joined[:: -(-len(joined) // _MAX_POINTS)]
        moments[keep] = _moments(members[keep])
        fits = {pair: value for pair, value in fits.items() if keep not in pair}
    return relabelled_by_root(labels, segment_of_supervoxel, root)
