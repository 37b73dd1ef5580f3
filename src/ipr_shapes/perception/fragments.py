"""Fragments of one surface joined to the segment they continue.

On real sensors the convexity graph leaves small pieces of curved objects as segments of their
own: slivers along a bowl's rim, a patch of a mug's ribbed side, a corner of a pouch. Each such
fragment shares a long stretch of its outline with one neighbouring segment along which the
surface runs on without a depth step, while an object, however small, is bounded by depth steps
(it stands in front of what is behind it) or touches its neighbours along a short contact.
A segment smaller than ``segmentation.fragment_area_m2`` is joined to the neighbour along which
its surface continues, when that continuation is at least ``segmentation.fragment_contact_share``
of its outline. Continuing means no step between neighbouring points and no crease between
their supervoxels' normals (two objects packed together touch along a crease), and the two
segments must have alike colours (docs/DESIGN_NOTES.md, "Fragments of curved surfaces joined by
their outline"), unless the piece's points lie on the smooth surface its neighbour makes around
it, within the sensor's scatter (``segmentation.fragment_surface``, on: a printed band, a label's
sliver, a cap's edge; a separate object touching the neighbour tangentially bends away from it),
or the piece lies on its neighbour (``segmentation.fragment_on_body``, opt-in: a cap, a lid; an
object resting on another lies on it too).

Then specks (``segmentation.fragment_specks``): a segment smaller than one supervoxel seed's
square that is mixed pixels at one segment's silhouette (seen edge-on, bordering only that
segment and the background or support behind it) joins that segment whatever its colour or
normals. A real sensor averages the two depths at a silhouette; a small object's visible part
faces the camera or borders a second object, or is seen past what is around it.
"""

from __future__ import annotations

import numpy as np

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.containers import support_axes, within_footprint
from ipr_shapes.perception.types import KnownPlane, Supervoxels


def join_fragments(
    labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    K: np.ndarray,
    rgb: np.ndarray,
    supervoxels: Supervoxels,
    config: PerceptionConfig,
    *,
    borders: tuple | None = None,
    support: KnownPlane | None = None,
    viewpoint: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Join small segments to the neighbour their surface continues into.

    Smallest first, a segment whose area (its pixels' footprints facing the camera, m^2) is
    under ``segmentation.fragment_area_m2`` joins the neighbouring segment with which it shares
    the most continuous pixel pairs (world points closer than ``fragment_gap_m``, their
    supervoxels' normals within ``fragment_bend_deg``: the surface runs on), when those are at
    least ``fragment_contact_share`` of its outline (its pixel pairs with any other label, the
    support and background included, both with depth) and the two mean chromaticities are within
    ``fragment_colour`` (objects packed tightly touch along much of a small one's outline; their
    colours tell them apart), or the segment's points continue the neighbour's smooth surface
    (``fragment_surface``, ``continues_surface``), or the segment lies on it
    (``fragment_on_body``, ``lies_on``). Then each speck (under ``supervoxels.seed_size_m``
    squared) that is mixed pixels at one segment's silhouette joins it (module doc). Joined
    segments add their areas and outlines, so a fragment of a fragment can join through it. A
    joined fragment takes its neighbour's label; every other label is kept (as
    ``containers.join_container_insides`` does), so objects elsewhere keep their ids.

    Args:
        labels: (H, W) int segment labels, 0 = none; segment_of_supervoxel: (M,) the segment of
            each supervoxel (relabelled the same way).
        points: (H, W, 3) world points (m); depth_m: (H, W) depth (m), 0 = no reading;
        K: (3, 3) camera intrinsics (px); rgb: (H, W, 3) colours; supervoxels: the frame's
            supervoxels (their normals; ``labels`` (H, W), -1 = none).
        borders: ``fragment_borders(labels, ...)`` if already computed (its arrays change in
            place when a fragment joins).
        support: the support plane (``fragment_on_body`` measures footprints and heights on
            it, ``fragment_surface`` reads the sensor's scatter from its inliers; None: those
            rules are off); viewpoint: (3,) camera centre, world (m) (the specks
            are judged edge-on from it; None: no specks).

    Returns:
        The relabelled (labels, segment_of_supervoxel); the inputs when nothing is joined.
    """
    seg = config.segmentation
    if seg.fragment_area_m2 <= 0 or labels.max() < 2:
        return labels, segment_of_supervoxel
    n = int(labels.max()) + 1
    if borders is None:
        borders = fragment_borders(labels, points, depth_m, K, rgb, supervoxels, config)
    area, colour, outline, continuous, touching = borders
    speck_m2 = config.supervoxels.seed_size_m**2 if seg.fragment_specks else 0.0
    order = [int(s) for s in np.argsort(area, kind="stable") if s > 0 and area[s] > 0]
    small = [s for s in order if area[s] < seg.fragment_area_m2]
    if not small:
        return labels, segment_of_supervoxel
    root = np.arange(n)
    # Fragments first, then specks (``fragment_specks``): a speck's mixed colours must not
    # move the mean colour a fragment's gate compares with.
    for specks in (False, True) if speck_m2 > 0 and viewpoint is not None else (False,):
        if specks:
            if not any(root[p] == p and area[p] < speck_m2 for p in small):
                break  # no speck left: the per-pixel measures are not needed
            current = root[labels]
            edge_on, seen = _edge_on_pixels(current, supervoxels, viewpoint, config)
        for piece in small:
            if root[piece] != piece or area[piece] >= (
                speck_m2 if specks else seg.fragment_area_m2
            ):
                continue  # joined, or grown by the fragments joined to it
            runs_on = touching if specks else continuous
            best = int(np.argmax(runs_on[piece]))
            # A speck's share is of its outline with segments: the rest is mixed pixels.
            rim = outline[piece, 1:] if specks else outline[piece]
            if runs_on[piece, best] == 0 or runs_on[piece, best] < (
                seg.fragment_contact_share * rim.sum()
            ):
                continue
            if (
                specks
                and (
                    edge_on[piece] * 2 <= seen[piece]  # it faces the camera: a surface
                    or np.count_nonzero(outline[piece, 1:]) > 1  # between two segments
                    or _behind(current, piece, depth_m, seg.fragment_gap_m)
                )
            ):
                continue
            if (
                not specks
                and not _alike(colour, piece, best, seg.fragment_colour)
                and not (
                    seg.fragment_on_body
                    and support is not None
                    and lies_on(root[labels], piece, best, points, depth_m, support, config)
                )
                and not (
                    seg.fragment_surface
                    and support is not None
                    and continues_surface(root[labels], piece, best, points, depth_m, support)
                )
            ):
                continue
            root[root == piece] = best
            for counts in (outline, continuous, touching):
                merge_counts(counts, piece, best)
            area[best] += area[piece]
            colour[best] += colour[piece]
    return relabelled_by_root(labels, segment_of_supervoxel, root)


def _edge_on_pixels(
    labels: np.ndarray, supervoxels: Supervoxels, viewpoint: np.ndarray, config: PerceptionConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Per label (L,), its pixels on supervoxels seen edge-on (the cosine of the normal with
    the ray to the camera under ``segmentation.contour_facing_cos``, as the contour split
    reads it) and its pixels on any supervoxel. Mixed pixels along a depth step lie along the
    rays between the two surfaces: a surface seen edge-on."""
    ray = np.asarray(viewpoint, dtype=np.float64)[None, :] - supervoxels.centres
    facing_cos = np.einsum("mc,mc->m", supervoxels.normals, ray) / np.maximum(
        np.linalg.norm(ray, axis=1), 1e-12
    )
    on = supervoxels.labels >= 0
    edge_on = facing_cos[supervoxels.labels[on]] < config.segmentation.contour_facing_cos
    count = int(labels.max()) + 1
    return (
        np.bincount(labels[on][edge_on], minlength=count),
        np.bincount(labels[on], minlength=count),
    )


def _behind(labels: np.ndarray, piece: int, depth_m: np.ndarray, gap_m: float) -> bool:
    """Whether segment ``piece`` is seen behind the background or support around it: along
    its 4-neighbour pixel pairs with label 0 (both with depth), the median depth step to them
    is nearer than ``-gap_m`` (m). Mixed pixels at a silhouette lie in front of what is
    behind it; a speck seen behind a wall or over a drawer's rim is a hidden object's part."""
    rows, cols = np.nonzero(labels == piece)
    height, width = labels.shape
    steps = []
    for d_row, d_col in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        r, c = rows + d_row, cols + d_col
        inside = (r >= 0) & (r < height) & (c >= 0) & (c < width)
        r, c, r0, c0 = r[inside], c[inside], rows[inside], cols[inside]
        pair = (labels[r, c] == 0) & (depth_m[r, c] > 0) & (depth_m[r0, c0] > 0)
        steps.append(depth_m[r, c][pair] - depth_m[r0, c0][pair])
    steps = np.concatenate(steps)
    return bool(steps.size and np.median(steps) < -gap_m)


def _alike(colour: np.ndarray, first: int, second: int, within: float) -> bool:
    """Whether two segments' mean chromaticities (from their (L, 3) RGB sums ``colour``) are
    at most ``within`` apart (L2)."""
    pair = colour[[first, second]]
    chroma = pair / np.maximum(pair.sum(axis=1), 1e-9)[:, None]
    return bool(np.linalg.norm(chroma[0] - chroma[1]) <= within)


def lies_on(
    labels: np.ndarray,
    piece: int,
    body: int,
    points: np.ndarray,
    depth_m: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
) -> bool:
    """Whether segment ``piece`` lies on segment ``body``: its footprint on the support within
    the body's (``containers.within_footprint``: the circle fitted to the body's footprint or
    its hull, grown by ``containers.margin_m``) and its median height above the support at least
    the body's. A cap, a lid or a band on a bottle's shoulder is carried by its body, on top of
    it; a separate object within another's footprint but under it (a ball wedged beneath a
    block resting on it) is not (docs/DESIGN_NOTES.md, "Fragments of curved surfaces joined by
    their outline").

    ``labels`` (H, W) int; ``points`` (H, W, 3) world (m); ``depth_m`` (H, W) (0: no reading,
    such pixels are left out); ``support`` the support plane.
    """
    axis_u, axis_v = support_axes(support)
    normal = np.asarray(support.normal, dtype=np.float64)
    footprints, heights = [], []
    for segment in (piece, body):
        pixels = np.flatnonzero((labels == segment) & (depth_m > 0))
        pixels = pixels[:: -(-pixels.size // _MAX_POINTS)] if pixels.size else pixels
        world = kernels.rows_at(points.reshape(-1, 3), pixels).astype(np.float64)
        footprints.append(np.stack([world @ axis_u, world @ axis_v], axis=1))
        heights.append(world @ normal)
    if len(heights[0]) == 0 or len(heights[1]) < 3:
        return False
    return bool(np.median(heights[0]) >= np.median(heights[1])) and within_footprint(
        footprints[0], footprints[1], config.containers
    )


def continues_surface(
    labels: np.ndarray,
    piece: int,
    body: int,
    points: np.ndarray,
    depth_m: np.ndarray,
    support: KnownPlane,
) -> bool:
    """Whether segment ``piece`` lies on the smooth surface of segment ``body`` around it.

    The body's points in a window around the piece (the piece's image bounding box grown by its
    own width and height on every side) are fitted with a quadric height field in their own
    principal frame; the surface is smooth there when their robust scatter about it (1.4826 x
    the median absolute deviation) is at most the support's scatter about its plane (the
    sensor's error over the frame: on a real sensor smooth over centimetres, so a local quadric
    absorbs most of it), and the piece continues it when its points' median distance from the
    fitted quadric, extrapolated, is at most twice that scatter (``_EXTRAPOLATED_SCATTER``). A
    printed band, a cap's edge or a sliver of a label runs on with its body's surface; a
    separate object touching a face tangentially (a ball wedged against a block, one resting on
    a box) bends away from it by d^2 / 2R at a distance d from the contact
    (docs/DESIGN_NOTES.md, "Fragments of curved surfaces joined by their outline").

    ``labels`` (H, W) int; ``points`` (H, W, 3) world (m); ``depth_m`` (H, W), 0: no reading
    (left out); ``support`` the support plane (its inlier points give the sensor's scatter).
    """
    height, width = labels.shape
    rows, cols = np.nonzero((labels == piece) & (depth_m > 0))
    if rows.size < _MIN_FIT_POINTS or len(support.points) < _MIN_FIT_POINTS:
        return False
    tall, wide = rows.max() - rows.min() + 1, cols.max() - cols.min() + 1
    r0, r1 = max(0, rows.min() - tall), min(height, rows.max() + tall + 1)
    c0, c1 = max(0, cols.min() - wide), min(width, cols.max() + wide + 1)
    near_rows, near_cols = np.nonzero((labels[r0:r1, c0:c1] == body) & (depth_m[r0:r1, c0:c1] > 0))
    if near_rows.size < _MIN_FIT_POINTS:
        return False
    step = -(-near_rows.size // _MAX_POINTS)
    near = points[near_rows[::step] + r0, near_cols[::step] + c0].astype(np.float64)
    step = -(-rows.size // _MAX_POINTS)
    own = points[rows[::step], cols[::step]].astype(np.float64)
    centre = near.mean(axis=0)
    axes = np.linalg.svd(near - centre, full_matrices=False)[2]

    def design(world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v, w = ((world - centre) @ axes.T).T
        return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=1), w

    matrix, height_near = design(near)
    try:  # normal equations: a 6 x 6 solve (lstsq's SVD of the whole design cost ~10 ms)
        coefficients = np.linalg.solve(matrix.T @ matrix, matrix.T @ height_near)
    except np.linalg.LinAlgError:
        return False  # the window's points do not span a surface (a line of pixels)
    scatter = _robust_scale(height_near - matrix @ coefficients)
    sensor = _robust_scale(support.signed_distance(np.asarray(support.points, np.float64)))
    if scatter > sensor:
        return False  # the body is no single smooth surface around the piece
    matrix, height_own = design(own)
    residual = np.median(np.abs(height_own - matrix @ coefficients))
    return bool(residual <= _EXTRAPOLATED_SCATTER * scatter)


def _robust_scale(residuals: np.ndarray) -> float:
    """1.4826 x the median absolute deviation of (N,) residuals (a Gaussian's sigma)."""
    return float(1.4826 * np.median(np.abs(residuals - np.median(residuals))))


#: The piece's median distance from its neighbour's quadric, in units of the neighbour's own
#: scatter about it, that still continues it: the piece lies beyond the fitted points, where the
#: quadric's error grows (a Gaussian's median absolute value is 0.67 sigma; twice the scatter
#: leaves room for that growth, while a ball of radius R tangent to the surface leaves it by
#: d^2 / 2R: 2.5 mm at 1 cm from the contact for R = 2 cm).
_EXTRAPOLATED_SCATTER = 2.0

#: Fewest points for a quadric fit (six coefficients, with room for the robust scale).
_MIN_FIT_POINTS = 30

#: Points of a segment used for its footprint (an even subset), as ``contours._MAX_POINTS``.
_MAX_POINTS = 2000


def fragment_borders(
    labels: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    K: np.ndarray,
    rgb: np.ndarray,
    supervoxels: Supervoxels,
    config: PerceptionConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``segment_borders`` with the fragments' gap and bend (``segmentation.fragment_gap_m``,
    ``fragment_bend_deg``): the border pass ``join_fragments`` needs and, when it joins
    nothing, ``join_thin_pieces`` too (its ``touching`` and ``area``), computed once."""
    seg = config.segmentation
    return segment_borders(
        labels, points, depth_m, K, rgb, supervoxels, seg.fragment_gap_m, seg.fragment_bend_deg
    )


def segment_borders(
    labels: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    K: np.ndarray,
    rgb: np.ndarray,
    supervoxels: Supervoxels,
    gap_m: float,
    bend_deg: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each segment's area and colour sum and, between every two labels, the neighbouring pixel
    pairs, from one compiled pass (``kernels.fragment_borders``).

    Returns ``area`` (L,) m^2 facing the camera, ``colour`` (L, 3) RGB sums, and the symmetric
    (L, L) counts ``outline`` (pixel pairs of two labels, both with depth; label 0 included),
    ``continuous`` (those whose world points are closer than ``gap_m`` and whose supervoxels'
    normals differ by at most ``bend_deg``; 180: any normals) and ``touching`` (as
    ``continuous`` with any normals: the thin-cylinder join's contacts), L = labels.max() + 1.
    Arguments as ``join_fragments``'.
    """
    area, colour, outline, continuous, touching = kernels.fragment_borders(
        labels,
        points,
        depth_m,
        rgb,
        supervoxels.labels,
        supervoxels.normals.astype(np.float64),
        float(gap_m),
        float(np.cos(np.radians(bend_deg))),
        _ANY_NORMALS_COS,
        1.0 / (float(K[0, 0]) * float(K[1, 1])),
        int(labels.max()) + 1,
    )
    return area, colour, outline + outline.T, continuous + continuous.T, touching + touching.T


#: The least cosine of "any normals" (a bend of 180 degrees), as ``segment_borders`` computes
#: a bend's cosine.
_ANY_NORMALS_COS = float(np.cos(np.radians(180.0)))


def merge_counts(counts: np.ndarray, piece: int, into: int) -> None:
    """Add row and column ``piece`` of the symmetric (L, L) pair ``counts`` to ``into``'s, in
    place, and clear ``piece``'s (the pairs within the joined segment drop)."""
    counts[into] += counts[piece]
    counts[:, into] += counts[:, piece]
    counts[into, into] = 0
    counts[piece] = 0
    counts[:, piece] = 0


def relabelled_by_root(
    labels: np.ndarray, segment_of_supervoxel: np.ndarray, root: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(labels, segment_of_supervoxel) with every label l replaced by ``root[l]`` (the inputs
    themselves when ``root`` joins nothing); supervoxel segments <= 0 stay."""
    if np.array_equal(root, np.arange(len(root))):
        return labels, segment_of_supervoxel
    segments = np.asarray(segment_of_supervoxel)
    relabelled = np.where(segments > 0, root[np.maximum(segments, 0)], segments)
    return root[labels].astype(labels.dtype), relabelled.astype(segment_of_supervoxel.dtype)
