"""The workspace: objects rest on the support, so what stands beyond its edge is not an object.

A real frame shows more than the table: a chair behind a round table, a trolley beyond its far
edge, a carpet. Their parts above the support's plane segment like objects. An object rests
on the support, so its footprint (its points projected along the support's normal) lies over
the support's seen extent; clutter beyond the table's edge lies outside it
(``drop_beyond_support``).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.types import KnownPlane


def support_outline(
    support: KnownPlane,
    on_support: np.ndarray,
    cell_m: float,
    standing: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The support's seen extent: ((2, 3) in-plane axes, (F, 3) 2D hull facets (a, b, c), with
    a x + b y + c <= 0 inside and (a, b) unit), or None when it spans no area.

    The extent is the convex hull, in the plane's coordinates (m), of the support points in
    the connected region of ``cell_m`` cells that holds most of the (N, 3) points seen on the
    support (world, m; cells one apart count as connected). The cells under the (S, 3)
    ``standing`` points (the segments' points, world, m) join the regions they touch: a pile
    that hides a band of the table from front to back bridges its two sides, while another
    surface at the table's height beyond it (a chair's seat) stays a separate region; the
    holes the objects hide in the table are inside the hull.
    """
    normal = np.asarray(support.normal, dtype=np.float64)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    axes = np.stack([u, np.cross(normal, u)])
    flat = np.asarray(on_support, dtype=np.float64) @ axes.T
    if len(flat) < 3:
        return None
    origin = flat.min(axis=0)
    cells = np.floor((flat - origin) / cell_m).astype(np.int64)
    shape = tuple(cells.max(axis=0) + 1)
    occupied = np.zeros(shape, dtype=bool)
    occupied[cells[:, 0], cells[:, 1]] = True
    # Grown by a cell, so that the gaps between sampled points far away do not split it.
    grown = ndimage.binary_dilation(occupied, structure=np.ones((3, 3), dtype=bool))
    if standing is not None and len(standing):
        under = np.floor((np.asarray(standing, dtype=np.float64) @ axes.T - origin) / cell_m)
        under = under.astype(np.int64)
        within = ((under >= 0) & (under < shape)).all(axis=1)
        grown[under[within, 0], under[within, 1]] = True
    regions, _ = ndimage.label(grown, structure=np.ones((3, 3), dtype=bool))
    region = regions[cells[:, 0], cells[:, 1]]
    largest = np.argmax(np.bincount(region)[1:]) + 1
    try:
        hull = ConvexHull(flat[region == largest])
    except QhullError:  # collinear or coincident points: no extent
        return None
    return axes, hull.equations


def drop_beyond_support(
    labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    valid: np.ndarray,
    support: KnownPlane,
    on_support: np.ndarray,
    support_share: float,
    config: PerceptionConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Remove segments whose footprint lies beyond the support's seen extent.

    A segment is beyond the support when less than ``segmentation.workspace_share`` of its
    points, projected onto the support's plane, fall within its seen extent (``support_outline``)
    grown by ``segmentation.workspace_margin_m`` (an object at the table's edge hides
    the edge beneath it). The test needs the support's extent to be seen: it applies only
    when the support holds at least ``support.min_fraction`` of the frame's depth pixels
    (``support_share``; the hidden floor of a packed bin, inferred from a few points between
    boxes, does not bound its boxes).

    Args:
        labels: (H, W) segment labels; segment_of_supervoxel: (M,) segment of each supervoxel.
        points: (H*W, 3) world points (m); valid: (H*W,) pixels with a depth reading.
        on_support: (N, 3) points (world, m) seen on the support (a subset suffices);
            support_share: share of the frame's depth pixels on the support.

    Returns:
        The (labels, segment_of_supervoxel) with those segments set to 0.
    """
    share = config.segmentation.workspace_share
    if share <= 0 or support_share < config.support.min_fraction:
        return labels, segment_of_supervoxel
    flat = labels.reshape(-1)
    labelled = np.flatnonzero((flat > 0) & valid)[::4]
    if labelled.size == 0:
        return labels, segment_of_supervoxel
    outline = support_outline(
        support, on_support, config.segmentation.workspace_cell_m, points[labelled]
    )
    if outline is None:
        return labels, segment_of_supervoxel
    axes, facets = outline
    footprint = points[labelled] @ axes.T
    outside = footprint @ facets[:, :2].T + facets[:, 2]
    inside = outside.max(axis=1) <= config.segmentation.workspace_margin_m
    segment = flat[labelled]
    count = np.bincount(segment)
    within = np.bincount(segment, weights=inside, minlength=len(count))
    seen = np.flatnonzero(count)
    beyond = seen[within[seen] < share * count[seen]]
    if beyond.size == 0:
        return labels, segment_of_supervoxel
    flat = np.where(np.isin(flat, beyond), 0, flat)
    segment_of_supervoxel = np.where(
        np.isin(segment_of_supervoxel, beyond), 0, segment_of_supervoxel
    )
    return flat.reshape(labels.shape), segment_of_supervoxel
