"""The support: the plane the objects rest on, chosen among a frame's planes, not the largest.

The largest plane of a frame is usually the table, but not always: a floor seen beyond a small
table holds more pixels than the table, and the coplanar tops of boxes packed in a bin hide the
bin's floor. ``choose_support`` takes the largest plane (the *dominant* plane, fitted by the
caller exactly as before) and keeps it unless what the frame shows says otherwise:

1. **A support is opaque; objects lie above it.** The dominant plane's extent (the convex
   hull, in the image, of its large connected pieces, less a rim of ``rim_px`` along its
   outline) must not show points more than ``drop_m`` below it: through a table nothing is
   seen. Where a share ``see_through`` of it does (gaps between boxes, their sides, a bin's
   floor), the plane is the tops of objects.
2. **A container's contents lie above its floor.** When the dominant plane lies between two
   walls perpendicular to it that rise above it beside it (a bin's far and near walls, or its
   left and right ones), the same share of the space between the walls (their own faces left
   out) below the plane also makes it the tops of objects: boxes packed so tightly that no gap
   shows, in a bin whose floor the sensor does not see, still show their sides and the bin's
   floor along the walls.

   The support under tops is **the lowest level reached**: the plane parallel to the tops at
   the ``low_percentile`` percentile of the heights of the points seen below them (in their
   extent, and between the walls): the bin's floor where it shows, else just under the lowest
   observed point of the objects, since the support is below all of them.
3. **Objects rest on the highest surface beneath them.** When the dominant plane is opaque,
   the opaque planes parallel to it and above it that are as large as a support must be
   (``min_fraction`` of the points) compete with it: each point stands on the highest of these
   planes whose footprint (seen from above) is beneath it, and points under a higher plane's
   footprint are that plane's body (a table's legs); the plane on which the most points stand is
   the support (a table above the floor it stands on).

The further planes come from RANSAC with removal (``candidates`` of them, each with at least
``min_candidate_fraction`` of the points); planes within ``level_tilt_deg`` of the dominant
plane's orientation are *levels* (parallel), planes within ``wall_tilt_deg`` of perpendicular
are *walls* (a bin's walls lean outwards by several degrees). The analysis runs on a grid of
about ``grid_width`` columns (every few rows and columns of the frame's organised points), so
its pixel settings do not depend on the image size.

The frame may be in any coordinates (camera or world); "up" is the dominant plane's normal
oriented towards the viewpoint (the camera sees the support's top face). No setting depends on
a data set; the measurements behind them are in
docs/experiments/2026-11-26-support-choice.md.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from ipr_shapes.geometry import order
from ipr_shapes.geometry.planes import Plane, fit_plane_ransac

#: 8-connectivity for the image-space components of a plane's inliers.
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class SupportChoiceConfig:
    """Settings of ``choose_support`` (module doc).

    Attributes:
        candidates: further planes extracted by RANSAC with removal (0: the dominant plane is
            the support, as the largest plane always was).
        iterations: RANSAC hypotheses per further plane.
        threshold_m: inlier distance of the further planes (m).
        min_candidate_fraction: a further plane needs this share of the analysed points.
        level_tilt_deg, wall_tilt_deg: a plane within this angle (deg) of parallel to the
            dominant plane is a level; within this angle of perpendicular, a wall.
        drop_m: points farther than this (m) from a plane are above or below it.
        see_through: share of a level's extent (less its rim) showing points below it from
            which it is the tops of objects (the rim holds what is seen beyond a table's edge,
            such as the floor further away).
        min_fraction: a level above the dominant plane competes as the support only with this
            share of the points (the support's own minimum, ``SupportConfig.min_fraction``).
        rim_px: the band (coarse pixels) of a level's extent along its outline that the
            see-through share leaves out (pixels mixed with what lies beyond its edge).
        piece_share: a plane's extent is its largest connected piece and the pieces with at
            least this share of its inliers.
        touch_px: a wall rises around a level when its largest piece comes within this many
            coarse pixels of the level's.
        low_percentile: the percentile of the heights of the points below the tops that sets
            the hidden support's level (a few outliers below the floor are ignored).
        grid_width: the analysis uses every n-th row and column of the frame, n such that
            about this many columns remain; ``rim_px`` and ``touch_px`` are pixels of that grid.
        seed: seed of the further planes' RANSAC (its own generator: the caller's is untouched).
    """

    candidates: int = 8
    iterations: int = 500
    threshold_m: float = 0.01
    min_candidate_fraction: float = 0.01
    level_tilt_deg: float = 10.0
    wall_tilt_deg: float = 30.0
    drop_m: float = 0.02
    see_through: float = 0.01
    min_fraction: float = 0.1
    low_percentile: float = 2.0
    rim_px: int = 2
    piece_share: float = 0.25
    touch_px: int = 10
    grid_width: int = 160
    seed: int = 0


@dataclass(frozen=True, eq=False)
class SupportChoice:
    """The chosen support and why.

    Attributes:
        normal: (3,) unit normal, up (towards the viewpoint).
        offset: the plane is {x : normal . x + offset = 0}.
        inliers: (K,) indices into the caller's usable points of the points on it (within the
            further planes' threshold; possibly none for a hidden floor).
        source: ``"dominant"`` (the largest plane), ``"upper level"`` (a parallel plane above
            the dominant one on which more stands: a table above a floor) or ``"below tops"``
            (the dominant plane is the tops of objects; the support is the lowest level
            reached below them).
        reason: one line for logs.
        measures: the figures the choice was made from (for logs and experiments).
    """

    normal: np.ndarray
    offset: float
    inliers: np.ndarray
    source: str
    reason: str
    measures: dict = field(default_factory=dict)

    @property
    def is_dominant(self) -> bool:
        """Whether the support is the dominant (largest) plane."""
        return self.source == "dominant"


@dataclass(eq=False)
class _Candidate:
    """A plane found on the coarse grid: unit normal oriented towards the viewpoint, offset,
    (h, w) inlier mask and ``share``, the piece share of ``_largest_piece``."""

    normal: np.ndarray
    offset: float
    mask: np.ndarray
    share: float

    @functools.cached_property
    def piece(self) -> np.ndarray:
        """(h, w) its large connected pieces (``_largest_piece``), found when first asked:
        only levels and walls have theirs read (a tilted plane's never, a level's other than
        the dominant one's only when the dominant plane is opaque)."""
        return _largest_piece(self.mask, self.share)


def choose_support(
    grid: np.ndarray,
    usable: np.ndarray,
    dominant: Plane,
    viewpoint: np.ndarray,
    config: SupportChoiceConfig = SupportChoiceConfig(),  # noqa: B008 (frozen)
) -> SupportChoice:
    """The support of a frame (module doc).

    Args:
        grid: (H, W, 3) organised points of the frame (m; any value where unusable).
        usable: (N,) flat pixel indices (into H * W) of the usable points.
        dominant: the largest plane, fitted to ``grid.reshape(-1, 3)[usable]`` (its inliers
            index ``usable``).
        viewpoint: (3,) camera centre in the grid's coordinates.
        config: settings.
    """
    viewpoint = np.asarray(viewpoint, dtype=np.float64)
    dominant = dominant.oriented_towards(viewpoint)
    up = np.asarray(dominant.normal, dtype=np.float64)
    keep = SupportChoice(
        up, float(dominant.offset), dominant.inliers, "dominant", "the largest plane"
    )
    if config.candidates <= 0:
        return keep
    height, width = grid.shape[:2]
    usable = np.asarray(usable, dtype=np.int64)
    usable_mask = np.zeros(height * width, dtype=bool)
    usable_mask[usable] = True
    step = max(1, round(width / config.grid_width))
    valid = usable_mask.reshape(height, width)[::step, ::step]
    coarse = np.ascontiguousarray(grid[::step, ::step], dtype=np.float64)
    shape = valid.shape
    flat_valid = np.flatnonzero(valid.ravel())
    points = coarse.reshape(-1, 3)[flat_valid]
    if len(points) < 10:
        return keep
    candidates = _candidates(points, flat_valid, shape, dominant, viewpoint, config)
    drop = config.drop_m
    parallel = np.cos(np.radians(config.level_tilt_deg))
    perpendicular = np.sin(np.radians(config.wall_tilt_deg))
    levels = [c for c in candidates if abs(c.normal @ up) >= parallel]  # the dominant first
    walls = [c for c in candidates if abs(c.normal @ up) <= perpendicular]
    heights = np.full(shape[0] * shape[1], np.nan)
    heights[flat_valid] = points @ up + dominant.offset
    heights = heights.reshape(shape)
    level_height = [order.median(heights[c.mask]) for c in levels]

    def assess(index: int) -> dict:
        """See-through share, extent, walls around and container of level ``index``."""
        level = levels[index]
        distance = np.full(shape[0] * shape[1], np.nan)
        distance[flat_valid] = points @ level.normal + level.offset
        distance = distance.reshape(shape)
        hull = _hull_mask(level.piece)
        # The extent's rim is left out: pixels mixed with what lies beyond the plane's edge.
        if config.rim_px > 0:  # (scipy erodes until nothing is left with 0 iterations)
            hull = ndimage.binary_erosion(hull, structure=_EIGHT, iterations=config.rim_px)
        extent = hull & valid
        below = extent & (distance < -drop)
        share = float(below.sum()) / max(int(extent.sum()), 1)
        around = _walls_around(level, walls, hull, valid, heights - level_height[index], config)
        inside = below
        container_share = 0.0
        pair = _between(level, around, coarse)
        if pair is not None:
            region = _hull_mask(level.piece | pair[0]["piece"] | pair[1]["piece"]) & valid
            for wall in around:
                region &= ~wall["piece"]
            inside = region & (distance < -drop)
            container_share = float(inside.sum()) / max(int(region.sum()), 1)
        return {
            "level_m": level_height[index],
            "below": below,
            "see_through": share,
            "walls": around,
            "container": pair is not None,
            "container_share": container_share,
            "inside": inside,
            "distance": distance,
        }

    def tops(assessed: dict) -> bool:
        return (
            assessed["see_through"] >= config.see_through
            or assessed["container_share"] >= config.see_through
        )

    first = assess(0)
    measures = {
        "see_through": round(first["see_through"], 4),
        "walls_around": len(first["walls"]),
        "container": first["container"],
        "container_share": round(first["container_share"], 4),
        "levels_m": [round(value, 4) for value in level_height],
    }
    if tops(first):
        return _below_tops(grid, usable, up, dominant, first, heights, config, measures, step)

    # The dominant plane is opaque: the opaque parallel planes above it that are as large as a
    # support compete with it (rule 3).
    minimum = config.min_fraction * len(points)
    rivals = [0]
    for index in range(1, len(levels)):
        if level_height[index] <= drop or levels[index].piece.sum() < minimum:
            continue
        if not tops(assess(index)):
            rivals.append(index)
    if len(rivals) == 1:
        return dataclasses.replace(keep, measures=measures)
    standing = _standing_counts(
        [levels[i] for i in rivals], [level_height[i] for i in rivals], coarse, valid, drop
    )
    measures["standing"] = {
        f"{level_height[i]:+.3f}": count for i, count in zip(rivals, standing, strict=True)
    }
    best = int(np.argmax(standing))
    if best == 0:
        return dataclasses.replace(keep, measures=measures)
    chosen = levels[rivals[best]]
    normal, offset, inliers = _refit(grid, usable, chosen.normal, chosen.offset, config.threshold_m)
    return SupportChoice(
        normal,
        offset,
        inliers,
        "upper level",
        f"a parallel plane {level_height[rivals[best]]:.3f} m above the largest one holds more: "
        f"{standing[best]} points stand on it against {standing[0]} (1/{step} resolution)",
        measures,
    )


def _usable_inliers(
    grid: np.ndarray, usable: np.ndarray, normal: np.ndarray, offset: float, threshold_m: float
) -> np.ndarray:
    """(K,) indices into ``usable`` (sorted flat pixel indices) of the usable points of the
    (H, W, 3) ``grid`` within ``threshold_m`` of the plane (normal, offset): one compiled pass
    over the grid, without gathering the usable points."""
    from ipr_shapes.geometry import (
        kernels,  # numba: only where it is needed (see ipr_shapes.geometry.planes)
    )

    flat = np.ascontiguousarray(grid.reshape(-1, 3), dtype=np.float64)
    hits = kernels.plane_inliers(
        flat, np.asarray(normal, dtype=np.float64), float(offset), threshold_m
    )
    # Both lists ascending: one merge finds the hits among the usable pixels.
    return kernels.positions_in_sorted(usable, hits)


def _refit(
    grid: np.ndarray, usable: np.ndarray, normal: np.ndarray, offset: float, threshold_m: float
) -> tuple[np.ndarray, float, np.ndarray]:
    """A plane found on the coarse grid refitted by least squares to its inliers among the
    frame's usable points (twice, as ``fit_plane_ransac`` refits): (unit normal, on the side of
    ``normal``; offset; inlier indices into ``usable``)."""
    from ipr_shapes.geometry import kernels

    flat = np.ascontiguousarray(grid.reshape(-1, 3), dtype=np.float64)
    for _ in range(2):
        inliers = usable[_usable_inliers(grid, usable, normal, offset, threshold_m)]
        if len(inliers) < 3:
            break
        centroid, scatter = kernels.centred_scatter(flat, inliers[:: max(1, len(inliers) // 20000)])
        _, vectors = np.linalg.eigh(scatter)
        refit = vectors[:, 0] if vectors[:, 0] @ normal >= 0 else -vectors[:, 0]
        normal, offset = refit, -float(refit @ centroid)
    normal = np.asarray(normal, dtype=np.float64)
    return normal, float(offset), _usable_inliers(grid, usable, normal, offset, threshold_m)


def _candidates(
    points: np.ndarray,
    flat_valid: np.ndarray,
    shape: tuple[int, int],
    dominant: Plane,
    viewpoint: np.ndarray,
    config: SupportChoiceConfig,
) -> list[_Candidate]:
    """The dominant plane then up to ``config.candidates`` further planes (RANSAC with removal)
    on the coarse points, each with its inlier mask (its largest connected piece is found when
    first asked, ``_Candidate.piece``)."""
    rng = np.random.default_rng(config.seed)
    count = shape[0] * shape[1]

    def candidate(normal: np.ndarray, offset: float, members: np.ndarray) -> _Candidate:
        mask = np.zeros(count, dtype=bool)
        mask[flat_valid[members]] = True
        mask = mask.reshape(shape)
        return _Candidate(normal, float(offset), mask, config.piece_share)

    distance = points @ dominant.normal + dominant.offset
    on_dominant = np.abs(distance) < config.threshold_m
    found = [candidate(dominant.normal, dominant.offset, np.flatnonzero(on_dominant))]
    remaining = np.flatnonzero(~on_dominant)
    min_inliers = max(50, int(config.min_candidate_fraction * len(points)))
    for _ in range(config.candidates):
        if len(remaining) < min_inliers:
            break
        plane = fit_plane_ransac(
            points[remaining],
            threshold_m=config.threshold_m,
            iterations=config.iterations,
            min_inliers=min_inliers,
            rng=rng,
            sample_size=1000,
        )
        if plane is None:
            break
        plane = plane.oriented_towards(viewpoint)
        found.append(candidate(plane.normal, plane.offset, remaining[plane.inliers]))
        remaining = np.delete(remaining, plane.inliers)
    return found


def _largest_piece(mask: np.ndarray, share: float) -> np.ndarray:
    """The inliers (h, w) of the large 8-connected pieces of ``mask`` once one-pixel gaps are
    closed: the largest and those with at least ``share`` of its inliers (the tops of boxes
    packed in a bin are several pieces apart by a few pixels of gap; a plane's far-away
    coincidental inliers are small pieces)."""
    from ipr_shapes.geometry import kernels  # numba: only where it is needed

    if not mask.any():
        return mask
    # Compiled: the closing, the pieces and their sizes in a few passes.
    return kernels.large_pieces(np.ascontiguousarray(mask), float(share))


def _hull_mask(mask: np.ndarray) -> np.ndarray:
    """(h, w) pixels inside the convex hull (image coordinates) of ``mask``'s pixels: a plane's
    extent, holes (what stands on it, or shows through it) included. A planar convex region
    projects to a convex region, so a table's hull is the table."""
    rows, columns = np.nonzero(mask)
    if len(rows) < 3:
        return mask.copy()
    try:
        hull = ConvexHull(np.column_stack([columns, rows]).astype(np.float64))
    except (QhullError, ValueError):
        return mask.copy()
    from ipr_shapes.geometry import kernels  # numba: only where it is needed

    # Compiled: every edge's test of every pixel, without a full-grid pass per edge.
    return kernels.inside_lines(
        np.ascontiguousarray(hull.equations, dtype=np.float64), mask.shape[0], mask.shape[1]
    )


def _walls_around(
    level: _Candidate,
    walls: list[_Candidate],
    extent: np.ndarray,
    valid: np.ndarray,
    heights: np.ndarray,
    config: SupportChoiceConfig,
) -> list[dict]:
    """The walls that rise around ``level``: their pieces come within ``touch_px`` of the
    level's pieces in the image (a dark gap, such as a bin's floor that the sensor does not see,
    may separate them), lie mostly outside the level's ``extent`` (h, w; the convex hull of its
    pieces: a container's walls bound it, while the faces of objects standing on a table lie
    within the table's extent) and reach above the level. ``heights`` (h, w) are heights above
    the level (m). Each wall: its unit normal (towards the viewpoint), offset and pieces."""
    if not level.piece.any() or config.touch_px <= 0:
        return []
    near = ndimage.binary_dilation(level.piece, structure=_EIGHT, iterations=config.touch_px)
    around = []
    for wall in walls:
        piece = wall.piece
        if not (piece & near).any() or (piece & extent).sum() > 0.5 * piece.sum():
            continue
        wall_heights = heights[piece & valid]
        if wall_heights.size < 10 or order.percentile(wall_heights, 98.0) <= config.drop_m:
            continue
        around.append({"normal": wall.normal, "offset": wall.offset, "piece": piece})
    return around


def _between(level: _Candidate, around: list[dict], coarse: np.ndarray) -> tuple[dict, dict] | None:
    """Two walls rising around ``level`` on opposite sides of its largest piece (a container's
    far and near walls, or its left and right walls: the level lies inside it), or None. Two
    walls are opposite when their normals are within 45 degrees of parallel or anti-parallel and
    the piece's centre lies between their planes."""
    if len(around) < 2:
        return None
    centre = coarse[level.piece].mean(axis=0)
    limit = np.cos(np.radians(45.0))
    for i, a in enumerate(around):
        for b in around[i + 1 :]:
            cosine = float(a["normal"] @ b["normal"])
            if abs(cosine) < limit:
                continue
            side_a = float(a["normal"] @ centre + a["offset"])
            side_b = float(b["normal"] @ centre + b["offset"])
            # Along a's normal, the centre is between the walls when it is in front of one and
            # behind the other (parallel normals) or in front of both (facing each other).
            if (side_a * side_b < 0) if cosine > 0 else (side_a > 0 and side_b > 0):
                return a, b
    return None


def _below_tops(
    grid: np.ndarray,
    usable: np.ndarray,
    up: np.ndarray,
    dominant: Plane,
    assessed: dict,
    heights: np.ndarray,
    config: SupportChoiceConfig,
    measures: dict,
    step: int,
) -> SupportChoice:
    """The support under the tops of objects: the lowest level reached below them (module doc,
    rule 2), within their extent and, inside a container, between its walls."""
    region = assessed["below"] | assessed["inside"]
    below = heights[region]
    below = below[np.isfinite(below)]
    if assessed["see_through"] >= config.see_through:
        reason = f"the largest plane shows {assessed['see_through']:.1%} of its extent below it"
    else:
        reason = (
            f"the largest plane lies between walls rising around it and "
            f"{assessed['container_share']:.1%} of the space between them is below it"
        )
    level = order.percentile(below, config.low_percentile) if below.size else -config.drop_m
    measures["support_level_m"] = round(level, 4)
    offset = float(dominant.offset) - level
    inliers = _usable_inliers(grid, usable, up, offset, config.threshold_m)
    return SupportChoice(
        up,
        offset,
        inliers,
        "below tops",
        f"{reason}: it is the tops of objects; the support is {-level:.3f} m below it "
        f"(the lowest level reached, {below.size} points below the tops at 1/{step} resolution)",
        measures,
    )


def _standing_counts(
    rivals: list[_Candidate],
    rival_heights: list[float],
    coarse: np.ndarray,
    valid: np.ndarray,
    drop: float,
) -> list[int]:
    """For each rival level, the points that stand on it: above it (by more than ``drop``),
    over its footprint (the convex hull of its pieces seen from above), not on a rival (the flat
    tops of objects do stand on it), and not over the footprint of a higher rival (a point rests on the highest surface beneath it;
    what lies under a higher rival, such as a table's legs and front panel, is that surface's
    own body)."""
    on_level = np.zeros(valid.shape, dtype=bool)
    for rival in rivals:
        on_level |= rival.mask
    free = (valid & ~on_level).ravel()
    points = coarse.reshape(-1, 3)
    up = rivals[0].normal
    axes = np.linalg.svd(np.eye(3) - np.outer(up, up))[0][:, :2]  # horizontal directions
    flat = points @ axes
    order = np.argsort(rival_heights)[::-1]
    taken = np.zeros(len(points), dtype=bool)
    counts = [0] * len(rivals)
    for index in order:
        rival = rivals[index]
        vertices = flat[rival.piece.ravel()]
        above = points @ rival.normal + rival.offset > drop
        counts[index] = int((free & _inside_hull(vertices, flat) & above & ~taken).sum())
        # A higher surface's body reaches its edges (a table top's front face).
        taken |= _inside_hull(vertices, flat, margin=drop)
    return counts


def _inside_hull(vertices: np.ndarray, query: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """(M,) whether the (M, 2) ``query`` points lie inside the convex hull of (N, 2)
    ``vertices``, widened by ``margin`` (none when the hull is degenerate)."""
    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError):
        return np.zeros(len(query), dtype=bool)
    inside = np.ones(len(query), dtype=bool)
    for a, b, c in hull.equations:
        inside &= a * query[:, 0] + b * query[:, 1] + c <= margin + 1e-9
    return inside
