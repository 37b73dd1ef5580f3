"""Open containers: join the pieces of a mug's, cup's or bowl's inside to the container.

The convexity graph (``segmentation.edge_weights``) cuts at concave edges, and the inside of an
open container is concave everywhere: a mug seen from above comes out as its outer wall plus
the inside in several pieces, none of them a well-segmented object alone. A piece P is the
inside of a larger segment C when, measured on the support plane:

- P meets C: their surfaces touch (4-neighbour pixels whose points are closer than
  ``containers.contact_gap_m``) or C's near wall hides P's lower part (C nearer by a depth step
  within ``containers.front_step_m``), along at least ``containers.min_contact_px``
  pixel pairs in all (a real sensor often loses the thin rim, so the inside only meets the
  outer wall by occlusion);
- P does not rise above C (its top at most ``containers.top_tolerance_m`` above C's): an inside is
  below the rim;
- P does not reach lower than C (its bottom at most ``containers.bottom_tolerance_m`` below C's):
  an inside sits on the container's floor, whereas a piece of another object seen under C's
  overhang stands on the support below C's lowest visible point;
- P does not stand in front of C: the pixel pairs at which P is nearer than C by such a step are at
  most ``containers.max_front_ratio`` of those along which they meet (an object resting on a box
  stands in front of it; an inside meets its container at the rim or behind its wall);
- P has C's colour: mean chromaticities (r, g, b) / (r + g + b), which shading does not change
  (an inside is darker than the outside), at most ``containers.max_chroma`` apart (L1);
- P lies within C's footprint on the support: at least ``containers.footprint_fraction`` of P's
  points project, with a margin of ``containers.margin_m``, either into the circle fitted to C's
  footprint, when one fits (RMS at most ``containers.circle_rms_m``, radius at most
  ``containers.max_radius_m``: a round wall, which surrounds its inside at its full height), or
  into the convex hull of C's footprint. A camera sees only the front half of a mug's outer
  wall, whose hull is a crescent that misses the inside; the circle does not. In the hull case
  C's points within ``containers.rim_radius_m`` of P's on the support must also reach P's top (98th
  percentile at most ``containers.top_tolerance_m`` below it): a rim surrounds an inside, whereas
  an object resting on a box rises above the box's face.

A real sensor's containers mostly fail those rules (``docs/experiments/2026-11-27-real-containers.md``):
seen from above, a bowl's or mug's largest segment is its inside (with the far rim), whose
filled footprint fits no circle, and the pieces are the near outer wall (which reaches below the
inside's floor) or an inside piece that carries the near rim (which rises above the wall's top).
The rules above presume the larger segment is the outer wall. So a pair also joins, whichever of
the two is the inside, when together they are one open container:

- they meet and the smaller does not stand in front of the larger (as above), and they have
  alike colours (``containers.max_chroma``);
- their rim is a circle: the points of both within ``containers.rim_band_m`` of their joint top
  (98th percentile) lie on a circle fitted robustly (Kasa fit, points beyond three robust
  standard deviations of the residuals, at least ``containers.circle_rms_m``, dropped and the
  circle refitted: flying pixels at the silhouette and a mug's handle), with at least
  ``containers.rim_inlier_share`` of them kept, an RMS of at most ``containers.circle_rms_m``
  and a radius of at most ``containers.max_radius_m`` and at least 1.2 cm (below, a small
  filled blob fits a circle as well);
- each of the two lies within that circle: ``containers.footprint_fraction`` of its points
  within the radius plus ``containers.margin_m`` on the support, a point below the rim also
  when its ray from the camera grazes the rim (mixed pixels at a far silhouette lie on their
  ray, behind the rim);
- a piece may stick out of the rim (``containers.piece_within_share`` of it within, the two
  together ``footprint_fraction``: a mug's handle) only when the rim is there: when the camera
  sees past the rim's place all round (``containers.rim_seen_past_share`` of its directions,
  ``_seen_past``), each piece must lie ``footprint_fraction`` within it. A circle through a
  tilted bowl's high arc and the top edge of a mug beside it runs through air
  (``docs/experiments/2026-11-27-touching-objects.md``, addendum).

The filled top of a box, a can or an object resting in a bowl above its rim fits no circle
(a filled disc's RMS is a quarter of its radius), and an object beside a container lies outside
the container's rim.

Pieces are joined one at a time, the pair that meets along the most pixel pairs first, and the
container's figures are recomputed after each join, so the inside's pieces that touch only
each other join in turn. The rules are strict because a looser footprint-only join also
merged different objects on ordinary scenes (``docs/DESIGN_NOTES.md``, "Open-container insides
are joined to the container"; measured with ``benchmarks.dev_perception --containers``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ipr_shapes.geometry import order
from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import ContainersConfig, PerceptionConfig
from ipr_shapes.perception.types import DepthView, KnownPlane

#: Points of a segment used for its footprint figures (an even subset).
_MAX_POINTS = 500


@dataclass(frozen=True, eq=False)
class _Segment:
    """What the rules need of one segment (heights and footprint on the support, metres).

    ``footprint`` (N, 2) and ``heights`` (N,) are an even subset of at most ``_MAX_POINTS`` of
    its points with depth. ``circle_rms_m`` and ``max_radius_m`` are the config's bounds on
    the fitted circle.
    """

    top: float
    bottom: float
    footprint: np.ndarray
    heights: np.ndarray
    chroma: np.ndarray
    circle_rms_m: float
    max_radius_m: float
    pixels: int = 0

    @property
    def size(self) -> int:
        """Pixels with depth of the segment (its subset's size when not given)."""
        return self.pixels or len(self.footprint)

    @functools.cached_property
    def hull(self) -> np.ndarray | None:
        """(F, 3) edge equations (unit normals) of the footprint's convex hull; None when the
        segment is seen as a line."""
        try:
            return ConvexHull(self.footprint).equations
        except QhullError:
            return None

    @functools.cached_property
    def circle(self) -> tuple[np.ndarray, float] | None:
        """(centre (2,), radius) of the least-squares (Kasa) circle through the footprint, or
        None when it does not fit (RMS distance above ``circle_rms_m``) or is larger than
        ``max_radius_m`` (``footprint_circle``)."""
        return footprint_circle(self.footprint, self.circle_rms_m, self.max_radius_m)


def footprint_circle(
    footprint: np.ndarray, circle_rms_m: float, max_radius_m: float
) -> tuple[np.ndarray, float] | None:
    """(centre (2,), radius) of the least-squares (Kasa) circle through the (N, 2) footprint
    (m, on the support), or None for fewer than 10 points, a circle fitted with an RMS
    distance above ``circle_rms_m`` or a radius above ``max_radius_m``: a round wall (mug,
    cup, bowl) seen from one side."""
    if len(footprint) < 10:
        return None
    origin = footprint.mean(axis=0)
    local = footprint - origin
    design = np.column_stack([local, np.ones(len(local))])
    solution, *_ = np.linalg.lstsq(design, (local**2).sum(axis=1), rcond=None)
    centre = solution[:2] / 2.0
    squared = solution[2] + centre @ centre
    if squared <= 0:
        return None
    radius = float(np.sqrt(squared))
    residual = np.linalg.norm(local - centre, axis=1) - radius
    if radius > max_radius_m or np.sqrt(np.mean(residual**2)) > circle_rms_m:
        return None
    return centre + origin, radius


def support_axes(support: KnownPlane) -> tuple[np.ndarray, np.ndarray]:
    """Two orthonormal (3,) world axes spanning the support plane: footprints on the support
    are a point's coordinates along them (m)."""
    normal = np.asarray(support.normal, dtype=np.float64)
    axis_u = np.cross(normal, [1.0, 0.0, 0.0])
    if np.linalg.norm(axis_u) < 0.1:
        axis_u = np.cross(normal, [0.0, 1.0, 0.0])
    axis_u /= np.linalg.norm(axis_u)
    return axis_u, np.cross(normal, axis_u)


def within_footprint(inner: np.ndarray, outer: np.ndarray, settings: ContainersConfig) -> bool:
    """Whether the (N, 2) footprint ``inner`` lies within the (M, 2) footprint ``outer`` (m, on
    the support): at least ``settings.footprint_fraction`` of its points within the circle
    fitted to ``outer`` (``footprint_circle``) or within its convex hull, either grown by
    ``settings.margin_m`` (an open container's inside within its wall, a cap within its
    bottle)."""
    fraction, margin = settings.footprint_fraction, settings.margin_m
    if len(inner) == 0:
        return False
    circle = footprint_circle(outer, settings.circle_rms_m, settings.max_radius_m)
    if circle is not None:
        distance = np.linalg.norm(inner - circle[0], axis=1)
        if np.mean(distance <= circle[1] + margin) >= fraction:
            return True
    try:
        hull = ConvexHull(outer).equations
    except (QhullError, ValueError):
        return False
    outside = inner @ hull[:, :2].T + hull[:, 2]
    return bool(np.mean(outside.max(axis=1) <= margin) >= fraction)


def join_container_insides(
    labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    valid: np.ndarray,
    depth_m: np.ndarray,
    rgb: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
    viewpoint: np.ndarray | None = None,
    view: DepthView | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Relabel the pieces of open containers' insides with their container's label.

    Args:
        labels: (H, W) int segment labels, 0 = none.
        segment_of_supervoxel: (M,) segment of each supervoxel (relabelled the same way).
        points: (H*W, 3) world points, metres; valid: (H*W,) pixels with a depth reading.
        depth_m: (H, W) depth, metres; rgb: (H, W, 3) uint8 colours.
        support: the support plane (heights and footprints are measured on it).
        viewpoint: (3,) the camera's centre, world (m), if known: a point on the ray from it
            through a container's rim counts as within the container (``_one_container``).
        view: the frame's depth image and camera, if known: a rim circle the camera sees past
            (``_seen_past``) holds only pieces wholly within it (``_one_container``).

    Returns:
        The relabelled (labels, segment_of_supervoxel); the inputs when nothing is joined.
    """
    if not config.containers.join_insides or labels.max() < 2:
        return labels, segment_of_supervoxel
    height, width = labels.shape
    contacts, fronts = _borders(
        labels, points.reshape(height, width, 3), depth_m, valid.reshape(height, width), config
    )
    meets = _meetings(contacts, fronts)
    if not any(count >= config.containers.min_contact_px for count in meets.values()):
        return labels, segment_of_supervoxel
    normal = support.normal / np.linalg.norm(support.normal)
    axis_u = np.cross(normal, [1.0, 0.0, 0.0])
    if np.linalg.norm(axis_u) < 0.1:
        axis_u = np.cross(normal, [0.0, 1.0, 0.0])
    axis_u /= np.linalg.norm(axis_u)
    axis_v = np.cross(normal, axis_u)
    frame = (support, axis_u, axis_v)
    rim_view = None if view is None else (view, frame)
    camera = None
    if viewpoint is not None:
        camera = (
            np.array([viewpoint @ axis_u, viewpoint @ axis_v]),
            float(support.signed_distance(viewpoint[None])[0]),
        )

    # Pixels with depth of every segment, from one compiled counting sort.
    flat = labels.reshape(-1)
    order, ids, starts = kernels.labelled_order(flat, valid)
    members = dict(zip(ids.tolist(), np.split(order, starts[1:]), strict=True))
    summaries: dict[int, _Segment] = {}

    def summary(segment: int) -> _Segment:
        if segment not in summaries:
            summaries[segment] = _summary(members[segment], points, rgb, frame, config)
        return summaries[segment]

    owner = {segment: segment for segment in members}
    verdicts: dict[tuple[int, int], bool] = {}
    joined = False
    while True:
        best = None
        for (a, b), count in meets.items():
            if count < config.containers.min_contact_px or (best is not None and count <= best[0]):
                continue
            piece, container = (a, b) if len(members[a]) < len(members[b]) else (b, a)
            if len(members[piece]) < 3:
                continue
            if fronts.get((piece, container), 0) > config.containers.max_front_ratio * count:
                continue
            if (piece, container) not in verdicts:
                verdicts[piece, container] = _is_inside(
                    summary(piece), summary(container), config
                ) or (
                    config.containers.join_rims
                    and _one_container(summary(piece), summary(container), config, camera, rim_view)
                )
            if verdicts[piece, container]:
                best = (count, piece, container)
        if best is None:
            break
        _, piece, container = best
        joined = True
        for segment, target in owner.items():
            if target == piece:
                owner[segment] = container
        # In pixel order, as the counting sort gives a segment's pixels: a summary's subset (every
        # k-th pixel) is then the same whichever joins made the segment.
        members[container] = np.sort(np.concatenate([members[container], members.pop(piece)]))
        summaries.pop(piece, None)
        summaries.pop(container, None)
        verdicts = {pair: v for pair, v in verdicts.items() if container not in pair}
        contacts = _relabelled(contacts, piece, container, ordered=False)
        fronts = _relabelled(fronts, piece, container, ordered=True)
        meets = _meetings(contacts, fronts)
    if not joined:
        return labels, segment_of_supervoxel
    largest = max(int(flat.max()), int(segment_of_supervoxel.max(initial=0)))
    lookup = np.arange(largest + 1, dtype=labels.dtype)
    for segment, target in owner.items():
        lookup[segment] = target
    return lookup[labels], lookup[segment_of_supervoxel].astype(segment_of_supervoxel.dtype)


def _meetings(contacts: dict, fronts: dict) -> dict:
    """{(a, b): pixel pairs, a < b} along which two segments' surfaces touch or one hides the
    other."""
    meets = dict(contacts)
    for (a, b), count in fronts.items():
        key = (min(a, b), max(a, b))
        meets[key] = meets.get(key, 0) + count
    return meets


def _borders(
    labels: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    valid: np.ndarray,
    config: PerceptionConfig,
) -> tuple[dict, dict]:
    """Where segments meet, from the 4-neighbour pixel pairs of two labels, both with depth.

    All pairs of segments at once (``tracking.contact_pixels`` counts one pair's contacts).
    Returns ``contacts`` {(a, b): count, a < b} of pairs whose world points are less than
    ``containers.contact_gap_m`` apart (the two surfaces meet there) and ``fronts`` {(nearer,
    farther): count} of pairs whose depths differ within ``containers.front_step_m`` (one segment
    stands in front of the other there).
    """
    low, high = config.containers.front_step_m
    # Only the labelled pixels' bounding box can hold borders.
    rows = np.flatnonzero(labels.any(axis=1))  # labels >= 0: any() is "some label > 0"
    cols = np.flatnonzero(labels.any(axis=0))
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    # Compiled (``kernels``): both passes over the pixel pairs without temporaries.
    contact_counts, front_counts = kernels.border_pair_counts(
        np.ascontiguousarray(labels[box]),
        points[box],
        depth_m[box],
        valid[box],
        float(config.containers.contact_gap_m),
        # The depth step is compared in the depth's own precision, as numpy compared it.
        depth_m.dtype.type(low),
        depth_m.dtype.type(high),
        int(labels.max()) + 1,
    )
    # The pairs in the order the dictionaries were built before (each pass's pairs sorted,
    # horizontal pass first): the joins take the first of equally strong pairs.
    contacts: dict[tuple[int, int], int] = {}
    fronts: dict[tuple[int, int], int] = {}
    for counts, found in ((contact_counts, contacts), (front_counts, fronts)):
        for direction in range(2):
            for a, b in zip(*np.nonzero(counts[direction]), strict=True):
                pair = (int(a), int(b))
                found[pair] = found.get(pair, 0) + int(counts[direction, a, b])
    return contacts, fronts


def _relabelled(counts: dict, piece: int, container: int, ordered: bool) -> dict:
    """``counts`` with ``piece`` renamed ``container`` (pairs within one segment dropped)."""
    merged: dict[tuple[int, int], int] = {}
    for (a, b), count in counts.items():
        a, b = (container if a == piece else a), (container if b == piece else b)
        if a != b:
            key = (a, b) if ordered else (min(a, b), max(a, b))
            merged[key] = merged.get(key, 0) + count
    return merged


def _summary(
    pixels: np.ndarray,
    points: np.ndarray,
    rgb: np.ndarray,
    frame: tuple[KnownPlane, np.ndarray, np.ndarray],
    config: PerceptionConfig,
) -> _Segment:
    """The rules' figures of a segment from its (N,) flat pixel indices with depth (N >= 1)."""
    support, axis_u, axis_v = frame
    count = int(pixels.size)
    pixels = pixels[:: -(-pixels.size // _MAX_POINTS)]
    world = kernels.rows_at(points, pixels)  # compiled: points[pixels]
    heights = support.signed_distance(world)
    footprint = np.stack([world @ axis_u, world @ axis_v], axis=1)
    colour = kernels.rows_at(rgb.reshape(-1, 3), pixels).astype(np.float64)
    colour += max(config.containers.chroma_floor, 1e-3)
    bottom, top = order.percentiles(heights, (2, 98))  # one partial sort for both
    return _Segment(
        top=float(top),
        bottom=float(bottom),
        footprint=footprint,
        heights=heights,
        chroma=(colour / colour.sum(axis=1, keepdims=True)).mean(axis=0),
        circle_rms_m=config.containers.circle_rms_m,
        max_radius_m=config.containers.max_radius_m,
        pixels=count,
    )


def _is_inside(piece: _Segment, container: _Segment, config: PerceptionConfig) -> bool:
    """Whether ``piece`` is (part of) the inside of ``container`` (module doc)."""
    if piece.top > container.top + config.containers.top_tolerance_m:
        return False
    if piece.bottom < container.bottom - config.containers.bottom_tolerance_m:
        return False
    if np.abs(piece.chroma - container.chroma).sum() > config.containers.max_chroma:
        return False
    fraction = config.containers.footprint_fraction
    if container.circle is not None:
        # A round wall (mug, cup, bowl) surrounds its inside at its full height, which the top
        # rule has checked.
        centre, radius = container.circle
        distance = np.linalg.norm(piece.footprint - centre, axis=1)
        if np.mean(distance <= radius + config.containers.margin_m) >= fraction:
            return True
    if container.hull is None:
        return False
    # Distance outside the hull: the largest signed distance to its edge lines.
    outside = piece.footprint @ container.hull[:, :2].T + container.hull[:, 2]
    if np.mean(outside.max(axis=1) <= config.containers.margin_m) < fraction:
        return False
    # Any other shape: its surface around the piece (a rim) must reach up to the piece's top.
    distance, _ = cKDTree(piece.footprint).query(
        container.footprint, distance_upper_bound=config.containers.rim_radius_m
    )
    around = container.heights[np.isfinite(distance)]
    return bool(
        around.size > 0
        and order.percentile(around, 98) >= piece.top - config.containers.top_tolerance_m
    )


def _rim_circle(
    footprint: np.ndarray, heights: np.ndarray, config: PerceptionConfig
) -> tuple[np.ndarray, float, float] | None:
    """(centre (2,), radius, height) on the support of the circle through the rim of the
    points with footprint (N, 2) and heights (N,) (metres), or None when their top is no
    circle.

    The rim is the points within ``containers.rim_band_m`` of the top (98th percentile; the
    height returned). The circle is a Kasa fit, refitted on its inliers until they stay the
    same (at most four fits): inliers are within three robust standard deviations (1.4826 x
    the median absolute residual) of the circle, and never fewer than those within
    ``containers.circle_rms_m``, so that a sensor's flying pixels at the silhouette and a mug's
    handle, which rise to the rim's height off its circle, do not bend it. It counts when at least ``containers.rim_inlier_share`` of the
    rim's points are inliers, their RMS distance to it is at most ``containers.circle_rms_m``
    and its radius at most ``containers.max_radius_m`` and at least ``circle_rms_m`` / 0.34
    (1.2 cm): a filled disc's points lie at an RMS distance of 0.34 r from their fitted circle
    of radius r, so a smaller blob (a cap, a corner seen from above) would fit as well as a rim.
    """
    settings = config.containers
    # The 98th percentile from a partial sort (linear interpolation between order statistics).
    position = 0.98 * (len(heights) - 1)
    low = int(position)
    high = min(low + 1, len(heights) - 1)
    ordered = np.partition(heights, [low, high])
    top = ordered[low] + (position - low) * (ordered[high] - ordered[low])
    rim = footprint[heights >= top - settings.rim_band_m]
    if len(rim) < 10:
        return None
    # Compiled (``kernels``): the fit and its refits in one pass each.
    cx, cy, radius, rms, share = kernels.robust_circle(
        np.ascontiguousarray(rim, dtype=np.float64), float(settings.circle_rms_m), 4
    )
    # A filled top's points lie at an RMS distance of 0.34 r from their fitted circle of radius
    # r (a uniform disc), so below circle_rms_m / 0.34 the RMS test cannot tell a rim from one.
    if (
        radius < settings.circle_rms_m / 0.34
        or share < settings.rim_inlier_share
        or radius > settings.max_radius_m
        or rms > settings.circle_rms_m
    ):
        return None
    centre = np.array([cx, cy])
    return centre, radius, float(top)


def _one_container(
    first: _Segment,
    second: _Segment,
    config: PerceptionConfig,
    camera: tuple[np.ndarray, float] | None = None,
    rim_view: tuple[DepthView, tuple[KnownPlane, np.ndarray, np.ndarray]] | None = None,
) -> bool:
    """Whether two segments are together one open container whose rim is a circle around
    both (module doc), whichever of them is the inside.

    ``camera``: the camera centre's footprint (2,) and height (m) on the support, if known. A
    point below the rim then also counts as within it when the ray from the camera to it
    grazes the rim (crosses the rim's height within ``containers.margin_m`` of the circle): a
    real sensor's mixed pixels at a silhouette lie on their ray between the rim and what is
    behind it (measured: 10-20 % of a white bowl's far piece lay up to 3 cm beyond its rim,
    1-3 cm above the table). A surface behind the container, seen over it, has its rays cross
    the rim's height beyond the far rim, mostly more than the margin beyond it.

    ``rim_view``: the frame's depth image and camera, and the support's frame (plane, in-plane
    axes u and v (3,) each), if known. A piece partly outside the rim (a handle, mixed pixels)
    then joins only when the rim is not seen past (``_seen_past``): a circle through the top
    of a tilted bowl and of an object beside it runs through air, where the camera sees what
    lies behind it; pieces wholly within the circle join either way (a tilted bowl's own
    pieces, whose top is no horizontal circle either).
    """
    settings = config.containers
    if np.abs(first.chroma - second.chroma).sum() > settings.max_chroma:
        return False
    circle = _rim_circle(
        np.concatenate([first.footprint, second.footprint]),
        np.concatenate([first.heights, second.heights]),
        config,
    )
    if circle is None:
        return False
    centre, radius, rim_height = circle
    reach = radius + settings.margin_m

    def within(part: _Segment) -> float:
        inside = np.linalg.norm(part.footprint - centre, axis=1) <= reach
        if camera is not None and camera[1] > rim_height:
            eye, eye_height = camera
            below = part.heights < rim_height
            # Where the ray from the camera to each point below the rim crosses its height.
            along = (rim_height - part.heights[below]) / (eye_height - part.heights[below])
            crossing = part.footprint[below] + along[:, None] * (eye - part.footprint[below])
            grazing = np.abs(np.linalg.norm(crossing - centre, axis=1) - radius)
            inside[below] |= grazing <= settings.margin_m
        return float(np.mean(inside))

    # The container holds the pair (``footprint_fraction`` of their points together) and each
    # lies mostly within it: a mug's handle sticks out of its rim, a neighbour lies beside it.
    shares = [within(part) for part in (first, second)]
    sizes = [part.size for part in (first, second)]
    held = (shares[0] * sizes[0] + shares[1] * sizes[1]) / max(sizes[0] + sizes[1], 1)
    if held < settings.footprint_fraction or min(shares) < settings.piece_within_share:
        return False
    # The leniencies for mixed pixels and a handle (a piece only partly within) presume a rim
    # that is there; a rim the camera sees past asks each piece to lie within it.
    return bool(
        rim_view is None
        or min(shares) >= settings.footprint_fraction
        or _seen_past(centre, radius, rim_height, rim_view, settings.margin_m, settings.rim_clear_m)
        <= settings.rim_seen_past_share
    )


#: Directions around a rim circle sampled by ``_seen_past``.
_RIM_SAMPLES = 72


def _seen_past(
    centre: np.ndarray,
    radius: float,
    height: float,
    rim_view: tuple[DepthView, tuple[KnownPlane, np.ndarray, np.ndarray]],
    margin_m: float,
    clear_m: float,
) -> float:
    """Share of the rim circle's directions at which the camera sees past the rim.

    The circle (centre (2,) and radius on the support's in-plane axes, at ``height`` above the
    support, metres) is sampled in ``_RIM_SAMPLES`` directions, each at the radius and
    ``margin_m`` inside and outside it (a rim fitted to a few mm). A direction is seen past
    when the camera observes, at all three points' pixels, a surface more than ``clear_m``
    farther than the point: there is air where the rim would be. A real rim blocks the view
    (its own points, the wall below it or the inside just behind it are within a few cm); a
    pixel without a reading, outside the image or nearer (an occluder) says nothing. The
    share is over the directions whose three points all project into the image.
    """
    view, (support, axis_u, axis_v) = rim_view
    normal = support.normal / np.linalg.norm(support.normal)
    angles = np.linspace(0.0, 2.0 * np.pi, _RIM_SAMPLES, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    # World points of footprint (u, v) at a height h: u axis_u + v axis_v + (h - offset) normal
    # (the axes are orthonormal and perpendicular to the unit normal).
    lift = (height - support.offset / np.linalg.norm(support.normal)) * normal
    past = np.ones(_RIM_SAMPLES, dtype=bool)
    seen = np.ones(_RIM_SAMPLES, dtype=bool)
    for r in (radius - margin_m, radius, radius + margin_m):
        footprint = centre + max(r, 0.0) * ring
        world = footprint[:, :1] * axis_u + footprint[:, 1:] * axis_v + lift
        z, observed = view.depths(world)
        seen &= view.in_image(world)
        with np.errstate(invalid="ignore"):
            past &= observed > z + clear_m  # NaN (nothing known) is False
    return float(np.sum(past & seen) / max(int(seen.sum()), 1))
