"""Pieces of one object that an occluder cut apart in the image, joined (beyond the paper).

The segmentation splits an object wherever something in front of it hides a band across it (a
bottle lying on a box, a can in front of a sugar box): the pieces do not touch in the image,
so neither the segmentation's graph nor the tracker's piece joins can see that they belong
together, and each piece gets its own hypotheses, all far too small. Two pieces are joined
when the evidence allows one solid:

- their colours are alike (the tracker's colour histograms, Bhattacharyya distance at most
  ``max_colour``), and their nearest points are within ``max_gap_m``;
- the convex hull of the two is consistent with what the camera saw: at most the unary
  constraints' tolerance of its voxels is in seen-free space or in a known wall beyond those
  the pieces' own hulls already are (two objects with the table seen between them fail: the
  space above the visible table is free), and at most ``max_inside_points`` observed points of
  other objects lie more than ``inside_margin_m`` inside it (the occluder is in front of the
  hidden link, not inside it).

Pairs are joined greedily, the most alike first, and the test is repeated on the joined
objects until no pair passes. Joined pieces get one set of hypotheses of the whole object, which
improved shapes on development scenes (docs/DESIGN_NOTES.md, "Pieces cut apart by an occluder
are joined for inference").
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ipr_shapes import voxels
from ipr_shapes.geometry.convex import convex_mesh
from ipr_shapes.perception import Perception
from ipr_shapes.perception.config import OccludedPiecesConfig
from ipr_shapes.perception.free_space import SeenSpace
from ipr_shapes.perception.occupancy import PlaneRegion, allowed_voxels, plane_regions, unary_report
from ipr_shapes.perception.tracking import (
    SegmentFeatures,
    colour_distance,
    merged_features,
    segment_features,
)
from ipr_shapes.perception.types import KnownPlane, PartialObject
from ipr_shapes.scene import Scene

logger = logging.getLogger(__name__)


def _offending_voxels(
    keys: np.ndarray, pitch_m: float, space: SeenSpace, regions: tuple[PlaneRegion, ...]
) -> int:
    """Voxels (``ipr_shapes.voxels`` keys at ``pitch_m``) seen free plus those inside a known wall
    (``ipr_shapes.perception.occupancy.unary_report``, the hypotheses' own count)."""
    # The vertices only feed the depth below the support, which is not used here.
    report = unary_report(np.zeros((1, 3)), keys, pitch_m, space, regions)
    return report.free_voxels + report.wall_voxels


def _hull_keys(points: np.ndarray, pitch_m: float) -> np.ndarray | None:
    """Voxel keys of the convex hull of (N, 3) points; None when they span no volume."""
    mesh = convex_mesh(points)
    return None if mesh is None else voxels.scanline_voxels(mesh[0], mesh[1], pitch_m)


#: Slack (m) of the bounding-box screens below: far above the rounding of coordinates of a
#: few metres (~1e-15 m), far below any distance the tests compare.
_SCREEN_SLACK_M = 1e-6


def _points_inside(points: np.ndarray, hull_points: np.ndarray, margin_m: float) -> int:
    """How many of (N, 3) ``points`` lie more than ``margin_m`` inside the convex hull of
    ``hull_points``.

    Only the points within the hull's bounding box shrunk by ``margin_m`` (less
    ``_SCREEN_SLACK_M``) are tested against its facets: a point deeper than ``margin_m`` inside
    the hull is that deep inside the box. Each tested point's signed distances are the same
    product as over all the points, so the count is the same; the product over all of them
    was (N, facets) large (0.8 GB and seconds on a bin of packed boxes)."""
    if len(points) == 0:
        return 0
    try:
        equations = ConvexHull(hull_points).equations
    except (QhullError, ValueError):
        return 0
    reach = margin_m - _SCREEN_SLACK_M
    low = np.min(hull_points, axis=0) + reach
    high = np.max(hull_points, axis=0) - reach
    points = points[np.all((points > low) & (points < high), axis=1)]
    if len(points) == 0:
        return 0
    signed = points @ equations[:, :3].T + equations[:, 3]
    return int(np.count_nonzero(np.all(signed < -margin_m, axis=1)))


def _within(a: np.ndarray, b: np.ndarray, gap_m: float) -> bool:
    """Whether the nearest of (N, 3) points ``a`` and (M, 3) points ``b`` are within ``gap_m``
    (their least ``np.linalg.norm`` distance at most ``gap_m``).

    Only the points of each within the other's bounding box grown by ``gap_m`` (and
    ``_SCREEN_SLACK_M``) are paired: the others are farther than that from every point of
    the other set. Each pair kept has the same distance as among all N x M, so the answer is
    the same; the N x M distances were most of the join's time on a bin of packed boxes."""
    reach = gap_m + _SCREEN_SLACK_M
    a = a[np.all((a >= np.min(b, axis=0) - reach) & (a <= np.max(b, axis=0) + reach), axis=1)]
    if len(a) == 0:
        return False
    b = b[np.all((b >= np.min(a, axis=0) - reach) & (b <= np.max(a, axis=0) + reach), axis=1)]
    if len(b) == 0:
        return False
    return float(np.min(np.linalg.norm(a[:, None] - b[None, :], axis=-1))) <= gap_m


def _joined(first: PartialObject, second: PartialObject) -> PartialObject:
    """One partial object of two pieces: the first's id, both pieces' pixels, points and
    facets (the second's facet numbers shifted past the first's)."""
    facet_of_point = None
    if first.facet_of_point is not None and second.facet_of_point is not None:
        shifted = np.where(
            second.facet_of_point >= 0, second.facet_of_point + len(first.facets), -1
        )
        facet_of_point = np.concatenate([first.facet_of_point, shifted])
    return dataclasses.replace(
        first,
        pixels=np.concatenate([first.pixels, second.pixels]),
        points=np.concatenate([first.points, second.points]),
        colours=np.concatenate([first.colours, second.colours]),
        facets=first.facets + second.facets,
        facet_of_point=facet_of_point,
        touches_border=first.touches_border or second.touches_border,
    )


def join_occluded_pieces(
    objects: tuple[PartialObject, ...],
    features: dict[int, SegmentFeatures],
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    config: OccludedPiecesConfig | None = None,
) -> tuple[tuple[PartialObject, ...], list[tuple[int, int]]]:
    """Join the pieces of objects cut apart by an occluder (module doc).

    Args:
        objects: one frame's partial objects (world frame, m).
        features: the frame's segment features by object id (``tracking.segment_features`` of
            its tracked labels), for the colour test.
        space: the frame's free-space map; None: nothing is joined.
        planes: the frame's support and walls.
        config: settings (defaults: ``OccludedPiecesConfig()``).

    Returns:
        The objects with every joined pair replaced by one object (the lower position's id, in
        the original order), and the (kept id, joined id) pairs in the order joined.
    """
    config = config or OccludedPiecesConfig()
    if not config.enabled or space is None or len(objects) < 2:
        return tuple(objects), []
    regions = plane_regions(planes, config.wall_min_thickness_m)
    pitch = space.grid.voxel_size_m
    current = list(objects)
    histograms = dict(features)
    own: dict[int, int] = {}  # offending voxels of each object's own hull, by id

    def own_offending(obj: PartialObject) -> int | None:
        if obj.id not in own:
            keys = _hull_keys(obj.points, pitch)
            own[obj.id] = -1 if keys is None else _offending_voxels(keys, pitch, space, regions)
        return None if own[obj.id] < 0 else own[obj.id]

    def solid(i: int, j: int) -> bool:
        """Whether objects ``current[i]`` and ``current[j]`` (i < j) pass the geometric tests
        (gap, hull against the seen space, foreign points inside)."""
        first, second = current[i], current[j]
        stride = max(config.point_stride, 1)
        if not _within(first.points[::stride], second.points[::stride], config.max_gap_m):
            return False
        own_first, own_second = own_offending(first), own_offending(second)
        union = np.concatenate([first.points, second.points])
        keys = _hull_keys(union, pitch)
        if own_first is None or own_second is None or keys is None:
            return False
        extra = _offending_voxels(keys, pitch, space, regions) - own_first - own_second
        tolerance = allowed_voxels(
            int(keys.size),
            config.free_space_tolerance,
            config.free_space_tolerance_voxels,
        )
        if extra > tolerance:
            return False
        others = [o.points for k, o in enumerate(current) if k not in (i, j)]
        inside = _points_inside(
            np.concatenate(others) if others else np.zeros((0, 3)),
            union,
            config.inside_margin_m,
        )
        return inside <= config.max_inside_points

    # A pair's verdict depends on its two objects and on the points of all the others, which
    # a join of two others leaves the same: kept until one of the pair is joined (each pass
    # over the pairs after a join would otherwise test every pair again).
    verdicts: dict[tuple[int, int], bool] = {}
    joins: list[tuple[int, int]] = []
    while True:
        best = None
        for i, first in enumerate(current):
            for j in range(i + 1, len(current)):
                second = current[j]
                if first.id not in histograms or second.id not in histograms:
                    continue
                colour = colour_distance(histograms[first.id], histograms[second.id])
                if colour > config.max_colour or (best is not None and colour >= best[0]):
                    continue
                pair = (int(first.id), int(second.id))
                if pair not in verdicts:
                    verdicts[pair] = solid(i, j)
                if verdicts[pair]:
                    best = (colour, i, j)
        if best is None:
            return tuple(current), joins
        colour, i, j = best
        first, second = current[i], current[j]
        verdicts = {
            pair: verdict
            for pair, verdict in verdicts.items()
            if first.id not in pair and second.id not in pair
        }
        logger.info(
            "objects %d and %d: pieces of one object behind an occluder (colour distance %.2f); "
            "joined",
            first.id,
            second.id,
            colour,
        )
        joins.append((int(first.id), int(second.id)))
        current[i] = _joined(first, second)
        own.pop(first.id, None)
        histograms[first.id] = merged_features(histograms[first.id], histograms[second.id])
        del current[j]


def join_first_frame_pieces(
    scene: Scene, perception: Perception, config: OccludedPiecesConfig | None = None
) -> tuple[Perception, list[tuple[int, int]]]:
    """``perception`` (an ``ipr_shapes.perception.Perception`` of ``scene``) with frame 0's partial
    objects passed through ``join_occluded_pieces``, and the joins made. Only the objects
    change: the label images keep the pieces' ids, so ``ipr-shapes segment`` output is unaffected."""
    config = config or OccludedPiecesConfig()
    if not config.enabled or not perception.objects or not perception.objects[0]:
        return perception, []
    frame = scene.frames[0]
    features = segment_features(
        perception.labels[0], frame.points_world(), frame.rgb, frame.depth_m
    )
    objects, joins = join_occluded_pieces(
        perception.objects[0], features, perception.free_space[0], perception.planes[0], config
    )
    if not joins:
        return perception, []
    return dataclasses.replace(perception, objects=[objects, *perception.objects[1:]]), joins
