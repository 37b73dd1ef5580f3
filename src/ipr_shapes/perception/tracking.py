"""Object identities across frames (paper Sec. III: partial objects O_{i,t} tracked over t).

Between two frames the robot pushes a few objects by some centimetres; everything else stays.
Each segment of frame t is matched to the objects known from earlier frames by a cost that
combines cues, each robust where the others fail:

- image overlap (IoU of masks): near 1 for objects that did not move, whatever their colour;
- colour: a normalised RGB histogram, unchanged by rigid motion (Bhattacharyya distance);
- proximity: the distance between 3D centroids relative to how far a push can move an object;
- visible size: the log ratio of the segments' visible areas (a pushed object turns, but a
  small object does not become a large one: this keeps a revealed small object from taking
  the id of a large one of the same colour that moved away);
- top height (weight 0 by default): a pushed object slides or turns but its highest point
  rarely changes much; with the size cue it no longer helped (``TrackingConfig``).

Assignment runs in two stages (Hungarian, scipy). First the confident matches: every segment
may also start a new object at cost ``max_match_cost``, so a pair costing more is never used
(the gate is part of the optimisation rather than applied to its result). Objects that did not
move, or moved a little, are settled here. Then the objects left without a segment and the
segments left without an object are matched among themselves with the looser
``elimination_cost`` gate: an object that was pushed far, or toppled and now shows other faces
and colours, is usually the one known object still unaccounted for, and the large segment in a
new place is usually it. (Opt-in, ``separated_piece_guard``: the second stage refuses a segment
whose surface stayed in place under another object's id while the object was seen elsewhere.)
A second-stage pair whose segment is a part pushed out of another matched object's previous
segment (a frame-0 union of two objects pushed apart) is undone: the segment starts a new
object and the part of the previous frame takes its id (``pushed_out_pieces``), which
``split_merged_objects`` carries back to frame 0. Objects that find no segment keep their id
for later frames (they may reappear). Each object is remembered by its last ``max_sightings`` sightings, and a segment's
cost to an object is its lowest cost to any of them (an object that was split or partly hidden
in the last frame is still recognised by an earlier, better view).

Three corrections follow the assignment, all for objects the segmentation splits: an
unmatched segment clearly larger than the piece that took an object's id, next to it and
resembling the object almost as well as that piece, takes the id instead
(``prefer_larger_pieces``); an object left
unmatched whose largest recent sighting was clearly larger than the (earlier) piece whose id a
segment took, next to it and almost as cheap, takes the segment (``prefer_larger_objects``: an
object split in an earlier frame and whole again); and touching pieces of similar colour whose
union resembles one known object better than each alone are joined into one segment with its
id (``merge_split_pieces``: an object split into comparable pieces in this frame, whose id
would otherwise land on either piece almost at random). Last, backwards in time: two known
objects that touched in an earlier frame, of which this frame matched one and not the other,
and whose union then resembles the matched segment better, were one object split in that frame
and become one id in every frame (``merge_split_objects``). After tracking, the converse:
an object first seen in a later frame that explains part of an earlier object's pixels in the
frame before (two touching objects one segment until a push separated them) takes that part,
back to frame 0 (``split_merged_objects``); and within one frame, a segment that holds a known
object left unmatched besides its own (two objects pushed into contact, segmented as one) gives
that object the pixels its colour singles out (``split_merged_segments``). And
(``moved_wholes``, on by default): an object that moved and whose segment, registered rigidly back onto the
frame before, covers both its own earlier segment and a neighbour's no longer seen, was one
object split there, and the two ids become one in every frame (``join_moved_wholes``).

The cues' weights, the two-stage assignment, the earlier sightings and each correction were
chosen on development scenes and checked on held-out ones, never on a benchmark suite; each kept
ids there that the steps before it lost (docs/DESIGN_NOTES.md, "Tracking cues and the two-stage
assignment", "Temporal consistency", "Objects split in an earlier frame are joined", "Objects
merged in frame 0 are split once pushed apart", "Objects pushed into one segment are split
again"; the defaults' figures are in docs/experiments/perception-config-notes.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from itertools import combinations

import numpy as np
from scipy.optimize import linear_sum_assignment

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig, TrackingConfig
from ipr_shapes.perception.temporal import ARRIVED, UNCHANGED, FrameChange, compare_frames

#: Histogram bins per RGB channel.
COLOUR_BINS = 6

#: Cost of an impossible pairing in the augmented assignment problem.
_FORBIDDEN = 1e9


@dataclass(frozen=True, eq=False)
class SegmentFeatures:
    """What tracking knows of a segment.

    Attributes:
        pixels: (N,) flat pixel indices, sorted and distinct.
        centroid: (3,) mean world point (m) of the pixels with depth.
        histogram: (COLOUR_BINS**3,) colour histogram summing to 1.
        top_m: top height (world z, m, 98th percentile).
        area: visible area up to a constant factor: the sum over pixels with depth of depth^2
            (a pixel's fronto-parallel footprint is depth^2 / (fx fy)); only ratios are used,
            so the intrinsics cancel. The pixel count when no depth is known.
    """

    pixels: np.ndarray
    centroid: np.ndarray
    histogram: np.ndarray
    top_m: float
    area: float


def segment_features(
    labels: np.ndarray, points: np.ndarray, rgb: np.ndarray, depth_m: np.ndarray | None = None
) -> dict[int, SegmentFeatures]:
    """Features of every segment k >= 1 in a (H, W) label image with (H, W, 3) world points,
    (H, W, 3) uint8 colours and the (H, W) depth (m, 0 = no reading; None = all valid)."""
    flat_points = points.reshape(-1, 3)
    # A pixel without depth back-projects to the camera centre: labels may cover depth holes, so
    # geometry comes from pixels with a reading (segments without any use all their pixels,
    # whose points are all zero). One compiled pass gives every segment's sums (``kernels``;
    # a frame has a dozen segments of up to tens of thousands of pixels).
    depth = np.ones(len(flat_points)) if depth_m is None else depth_m.reshape(-1)
    ids, order, starts, with_depth, used, point_sums, used_z, histograms, footprints = (
        kernels.segment_sums(
            labels.reshape(-1), flat_points, rgb.reshape(-1, 3), depth, COLOUR_BINS
        )
    )
    centroids = point_sums / np.maximum(used, 1)[:, None]
    tops = _grouped_percentile(used_z, used, 98.0)
    features = {}
    for index, label in enumerate(ids.tolist()):
        histogram = histograms[index].astype(np.float64)
        area = float(footprints[index])
        features[label] = SegmentFeatures(
            order[starts[index] : starts[index + 1]],
            centroids[index],
            histogram / histogram.sum(),
            float(tops[index]),
            area if area > 0 else float(starts[index + 1] - starts[index]),
        )
    return features


def _grouped_percentile(values: np.ndarray, counts: np.ndarray, percentile: float) -> np.ndarray:
    """(G,) ``np.percentile`` (linear interpolation) of each of G consecutive runs of (N,)
    ``values`` whose (G,) lengths are ``counts``; nan for empty runs. One partial sort per
    group and numpy's own interpolation (``_lerp``), so the values are the same, without
    ``np.percentile``'s per-call overhead."""
    result = np.full(len(counts), np.nan)
    first = 0
    for group, count in enumerate(counts.tolist()):
        if count == 0:
            continue
        virtual = (count - 1) * (percentile / 100.0)
        lower = int(np.floor(virtual))
        upper = min(lower + 1, count - 1)
        gamma = virtual - lower
        chosen = np.partition(values[first : first + count], (lower, upper))
        a, b = chosen[lower], chosen[upper]
        difference = b - a
        result[group] = b - difference * (1 - gamma) if gamma >= 0.5 else a + difference * gamma
        first += count
    return result


def _colour_codes(colours: np.ndarray) -> np.ndarray:
    """Histogram bin (N,) int64 of (N, 3) uint8 RGB colours, ``COLOUR_BINS`` per channel."""
    bins = (colours.astype(np.int64) * COLOUR_BINS) // 256
    return (bins[:, 0] * COLOUR_BINS + bins[:, 1]) * COLOUR_BINS + bins[:, 2]


def match_costs(
    known: dict[int, SegmentFeatures],
    segments: dict[int, SegmentFeatures],
    image_size: int,
    config: TrackingConfig,
) -> tuple[list[int], list[int], np.ndarray]:
    """Cost matrix (segments x known objects) of explaining each segment as each known object.

    Mask overlaps come from one map of this frame's segments, which are disjoint, so each
    known object's overlaps with all of them cost one pass over its pixels and are exact. (The
    known objects' sightings may come from different frames and overlap one another: a map of
    them would give shared pixels to one of them only, the one later in id order, so an
    object's overlap, and the assignment, would depend on how the objects happen to be
    numbered.) Returns the segment ids, the known ids (sorted) and the (S, K) costs, each in
    [0, overlap + colour + distance + size + height weights].
    """
    segment_ids, known_ids = sorted(segments), sorted(known)
    row_of = np.zeros(image_size, dtype=np.int64)  # row + 1 of the segment, 0 = none
    for row, segment_id in enumerate(segment_ids):
        row_of[segments[segment_id].pixels] = row + 1
    shared = np.zeros((len(segment_ids), len(known_ids)))
    for column, object_id in enumerate(known_ids):
        counts = np.bincount(row_of[known[object_id].pixels], minlength=len(segment_ids) + 1)
        shared[:, column] = counts[1:]
    segment_sizes = np.array([segments[s].pixels.size for s in segment_ids], dtype=float)
    known_sizes = np.array([known[o].pixels.size for o in known_ids], dtype=float)
    overlap = shared / (segment_sizes[:, None] + known_sizes[None, :] - shared)
    # Bhattacharyya distance between colour histograms, in [0, 1].
    root_segment = np.sqrt(np.stack([segments[s].histogram for s in segment_ids]))
    root_known = np.sqrt(np.stack([known[o].histogram for o in known_ids]))
    colour = np.sqrt(np.clip(1.0 - root_segment @ root_known.T, 0.0, None))
    centroid_segment = np.stack([segments[s].centroid for s in segment_ids])
    centroid_known = np.stack([known[o].centroid for o in known_ids])
    distance = np.linalg.norm(centroid_segment[:, None] - centroid_known[None], axis=-1)
    area_segment = np.array([segments[s].area for s in segment_ids])
    area_known = np.array([known[o].area for o in known_ids])
    size_change = np.abs(np.log(area_segment[:, None] / area_known[None, :]))
    top_segment = np.array([segments[s].top_m for s in segment_ids])
    top_known = np.array([known[o].top_m for o in known_ids])
    height = np.abs(top_segment[:, None] - top_known[None, :])
    cost = _combined_cost(overlap, colour, distance, size_change, height, config)
    return segment_ids, known_ids, cost


def _combined_cost(
    overlap: np.ndarray,
    colour: np.ndarray,
    distance_m: np.ndarray,
    size_change: np.ndarray,
    height_m: np.ndarray,
    config: TrackingConfig,
) -> np.ndarray:
    """The matching cost from its cues (arrays of one shape): mask IoU, Bhattacharyya colour
    distance, centroid distance (m), |log| of the visible-area ratio, top-height change (m)."""
    cost = (
        config.overlap_weight * (1.0 - overlap)
        + config.colour_weight * colour
        + config.distance_weight * np.minimum(distance_m / config.max_motion_m, 1.0)
        + config.size_weight * np.minimum(size_change / np.log(config.size_ratio_scale), 1.0)
    )
    if config.height_weight > 0:
        cost = cost + config.height_weight * np.minimum(height_m / config.height_scale_m, 1.0)
    return cost


def colour_distance(first: SegmentFeatures, second: SegmentFeatures) -> float:
    """Bhattacharyya distance in [0, 1] between two segments' colour histograms."""
    affinity = float(np.sqrt(first.histogram) @ np.sqrt(second.histogram))
    return float(np.sqrt(max(1.0 - affinity, 0.0)))


def pair_cost(segment: SegmentFeatures, known: SegmentFeatures, config: TrackingConfig) -> float:
    """``match_costs`` of one segment against one sighting, without the (H*W,) map of where
    known objects were seen (a segment's pixels are distinct, so its overlap is a set
    intersection)."""
    shared = _shared_count(segment.pixels, known.pixels)
    overlap = shared / (segment.pixels.size + known.pixels.size - shared)
    cues = (
        overlap,
        colour_distance(segment, known),
        float(np.linalg.norm(segment.centroid - known.centroid)),
        abs(float(np.log(segment.area / known.area))),
        abs(segment.top_m - known.top_m),
    )
    return float(_combined_cost(*(np.float64(cue) for cue in cues), config))


def _shared_count(first: np.ndarray, second: np.ndarray) -> int:
    """Number of values common to two (N,) and (M,) sorted arrays of distinct flat pixel
    indices: binary searches of the shorter in the longer, several times faster than
    ``np.intersect1d`` (which sorts their concatenation) on segments of thousands of pixels."""
    needles, haystack = (first, second) if first.size <= second.size else (second, first)
    if needles.size == 0:
        return 0
    found = np.searchsorted(haystack, needles)
    found[found == haystack.size] = 0  # past the end: compare with any value (not equal)
    return int(np.count_nonzero(haystack[found] == needles))


def extent_m(pixels: np.ndarray, points: np.ndarray, depth_m: np.ndarray | None) -> float:
    """A segment's size (m): the diagonal of the box spanned along its principal axes by the
    2nd to 98th percentiles of its world points, for (N,) flat pixel indices of a frame with
    (H, W, 3) world points (m) and (H, W) depth (m, 0 = no reading; None = all valid). The
    percentiles keep a few flying pixels at the outline from setting the size; 0 for fewer than
    three points with depth."""
    if depth_m is not None:
        pixels = pixels[depth_m.reshape(-1)[pixels] > 0]
    if pixels.size < 3:
        return 0.0
    points_k = points.reshape(-1, 3)[pixels]
    centred = points_k - points_k.mean(axis=0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    along = centred @ axes
    low, high = np.percentile(along, [2.0, 98.0], axis=0)
    return float(np.linalg.norm(high - low))


def merged_features(first: SegmentFeatures, second: SegmentFeatures) -> SegmentFeatures:
    """Features of the union of two disjoint segments of one frame.

    Centroid and histogram are the two's means weighted by pixel count (exact for the
    histogram; the centroid also weighs pixels without depth, a small bias for a cue scaled by
    ``max_motion_m``), the top the higher of the two tops (the union's 98th percentile lies
    between them), the area the sum.
    """
    n_first, n_second = first.pixels.size, second.pixels.size
    total = n_first + n_second
    return SegmentFeatures(
        np.sort(np.concatenate([first.pixels, second.pixels])),
        (n_first * first.centroid + n_second * second.centroid) / total,
        (n_first * first.histogram + n_second * second.histogram) / total,
        max(first.top_m, second.top_m),
        first.area + second.area,
    )


def contact_pixels(
    first: np.ndarray,
    second: np.ndarray,
    width: int,
    points: np.ndarray,
    max_gap_m: float,
    valid: np.ndarray | None = None,
) -> int:
    """Number of 4-neighbour pixel pairs between two (N,) flat pixel index sets of an image
    ``width`` pixels wide whose (H*W, 3) world points (m) are at most ``max_gap_m`` apart: the
    two surfaces meet there, rather than one occluding the other. With ``valid`` ((H*W,) bool,
    pixels with a depth reading), pairs with a pixel without depth do not count (labels cover
    the holes sensors leave at silhouettes, where such pixels would all sit at the camera)."""
    size = len(points)
    marked = np.zeros(size, dtype=bool)
    marked[second] = True
    column = first % width
    count = 0
    for step, inside in (
        (1, column < width - 1),
        (-1, column > 0),
        (width, first < size - width),
        (-width, first >= width),
    ):
        here = first[inside]
        here = here[marked[here + step]]
        if valid is not None:
            here = here[valid[here] & valid[here + step]]
        gap = np.linalg.norm(points[here] - points[here + step], axis=1)
        count += int(np.count_nonzero(gap <= max_gap_m))
    return count


def assign_segments(
    cost: np.ndarray,
    new_cost: float,
    elimination_cost: float,
    gated_elimination: bool = False,
    refused: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """(P, 2) (segment row, known column) pairs of a (S, K) cost matrix, in two stages.

    Stage 1 solves the augmented assignment problem in which every segment may instead start
    a new object at ``new_cost`` and every known object may stay unmatched at no cost, so no
    pair dearer than ``new_cost`` is used. Stage 2 matches the segments and objects stage 1 left
    alone, among themselves, with pairs up to ``elimination_cost`` (module doc). With
    ``gated_elimination`` stage 2 is the same augmented problem with ``elimination_cost`` as
    the gate (opt-in); without it (the default) it pairs every leftover segment it can and then
    drops the pairs above the gate, so a segment that matches nothing within the gate can
    take, and waste, the one object another leftover segment matched within it
    (docs/DESIGN_NOTES.md, "The elimination stage"). ``refused``, None or a function of
    stage 2's (L,) segment rows giving an (L, K) bool mask: pairs stage 2 may not make
    (``separated_pieces``, evaluated for the leftover segments only); stage 1 is unaffected.
    """
    n_segments, n_known = cost.shape
    rows, cols = _gated_assignment(cost, new_cost)
    pairs = [np.stack([rows, cols], axis=1)]
    left_rows = np.setdiff1d(np.arange(n_segments), rows)
    left_cols = np.setdiff1d(np.arange(n_known), cols)
    if left_rows.size and left_cols.size:
        rest = cost[np.ix_(left_rows, left_cols)]
        if refused is not None:
            # Just above the gate, not forbidden: a refused pair the optimum would have left
            # dropped anyway (above the gate) must not reshuffle the others' pairs.
            above = np.maximum(rest, np.nextafter(elimination_cost, np.inf))
            rest = np.where(refused(left_rows)[:, left_cols], above, rest)
        if gated_elimination:
            rows, cols = _gated_assignment(rest, elimination_cost)
        else:
            rows, cols = linear_sum_assignment(rest)
            keep = rest[rows, cols] <= elimination_cost
            rows, cols = rows[keep], cols[keep]
        pairs.append(np.stack([left_rows[rows], left_cols[cols]], axis=1))
    return np.concatenate(pairs).astype(np.int64)


def separated_pieces(
    segments: dict[int, SegmentFeatures],
    segment_ids: list[int],
    known_ids: list[int],
    seen_last_frame: set[int],
    previous_labels: np.ndarray,
    previous_points: np.ndarray,
    points: np.ndarray,
    previous_rgb: np.ndarray,
    rgb: np.ndarray,
    depth_m: np.ndarray | None,
    previous_depth_m: np.ndarray | None,
    config: TrackingConfig,
) -> np.ndarray:
    """(len(segment_ids), K) bool: the second-stage pairs refused because the segment is a
    piece a push left in place out of another object's segment, not the free object
    (``TrackingConfig.separated_piece_guard``, opt-in).

    The pair (segment, known object ``k``) is refused when at least ``separated_min_share`` of
    the segment's pixels with depth show, at the same pixel, a surface within
    ``separated_unchanged_m`` of the previous frame's and of its colour (each channel within
    ``separated_unchanged_rgb``: a flat top slid along itself keeps its depth, not the colour
    of what lay there) and were labelled, in the previous frame, with a tracked id other than
    ``k`` (and not 0), and ``k`` itself was seen in the previous frame (``seen_last_frame``):
    ``k`` was then elsewhere, and a surface that stayed in place cannot be it. An object not
    seen the frame before may have been inside the other's segment, so its pairs are left to
    the cost. Pixels are compared in place, so a moved camera makes surfaces differ and
    refuses nothing.

    Args:
        segments: this frame's segments by id; segment_ids: those to check (the mask's rows);
            known_ids: the cost matrix's columns; seen_last_frame: ids seen in the previous
            frame; previous_labels: (H, W) int tracked ids of the previous frame;
            previous_points, points: (H, W, 3) world points (m) of the previous and this
            frame; previous_rgb, rgb: their (H, W, 3) uint8 colours; depth_m,
            previous_depth_m: (H, W) depth (m, 0 = no reading) or None (all valid).
    """
    refused = np.zeros((len(segment_ids), len(known_ids)), dtype=bool)
    columns = [c for c, k in enumerate(known_ids) if k in seen_last_frame]
    if not columns or previous_labels.shape != points.shape[:2]:
        return refused
    flat_previous = previous_labels.reshape(-1)
    flat_points, flat_previous_points = points.reshape(-1, 3), previous_points.reshape(-1, 3)
    valid = np.ones(flat_previous.size, dtype=bool)
    for depth in (depth_m, previous_depth_m):
        if depth is not None:
            valid &= depth.reshape(-1) > 0
    limit = config.separated_unchanged_m**2
    flat_rgb, flat_previous_rgb = rgb.reshape(-1, 3), previous_rgb.reshape(-1, 3)
    for row, segment_id in enumerate(segment_ids):
        pixels = segments[segment_id].pixels
        pixels = pixels[valid[pixels]]
        if not pixels.size:
            continue
        least = config.separated_min_share * pixels.size
        moved = ((flat_points[pixels] - flat_previous_points[pixels]) ** 2).sum(axis=1)
        pixels = pixels[moved <= limit]
        recoloured = np.abs(
            flat_rgb[pixels].astype(np.int16) - flat_previous_rgb[pixels].astype(np.int16)
        ).max(axis=1)
        stayed = flat_previous[pixels[recoloured <= config.separated_unchanged_rgb]]
        stayed = stayed[stayed > 0]
        if stayed.size < least:
            continue
        ids, counts = np.unique(stayed, return_counts=True)
        for column in columns:
            others = stayed.size - counts[ids == known_ids[column]].sum()
            refused[row, column] = others >= least
    return refused


def _separated_rows(rows: np.ndarray, *, segment_ids: list[int], **kwargs) -> np.ndarray:
    """``separated_pieces`` for the (L,) cost-matrix ``rows`` of ``segment_ids`` only (the
    segments the first stage left): (L, K) bool."""
    return separated_pieces(segment_ids=[segment_ids[r] for r in rows], **kwargs)


def pushed_out_pieces(
    assignment: dict[int, int],
    cost: np.ndarray,
    segment_ids: list[int],
    known_ids: list[int],
    segments: dict[int, SegmentFeatures],
    seen_last_frame: set[int],
    previous_labels: np.ndarray,
    previous_frame: tuple[np.ndarray, np.ndarray, np.ndarray | None],
    change: Callable[..., FrameChange],
    config: TrackingConfig,
) -> tuple[dict[int, int], list[tuple[int, int, np.ndarray]]]:
    """Take a free old id back from a part pushed out of another object's segment.

    A frame-0 segment often holds two touching objects; a push separates them, one keeps the
    union's id and the assignment's second stage may hand the other, which no known object
    resembles within ``max_match_cost``, the free id of some object hidden now
    (docs/DESIGN_NOTES.md, "The elimination stage"). Its earlier pixels then stay under the
    union's id for good: ``split_merged_objects`` splits only for objects first seen later.

    A segment ``s`` matched to an object ``k`` seen in the previous frame at a cost above
    ``max_match_cost`` (a pair only the second stage makes) is taken as a part pushed out of
    another matched object ``x`` labelled in the previous frame when splitting ``x`` explains
    this frame better than the pair, by ``split_merged_objects``' own test (its parts,
    ``_split_parts``, and costs) with the pair's cost where that test has a new object's:
    ``x``'s previous-frame pixels with depth, followed into this frame (``change``), split into
    the part now seen as ``s`` (or also gone) and the rest, each at least ``split_min_share``
    of them (and ``split_min_px``), and **each side better on its own**: ``x``'s segment costs less
    against the rest than against all of them (the part was not ``x``'s own surface: an
    object that merely moved explains its old place no worse whole), and ``s`` costs less
    against the part than against ``k`` (the sum then gains, more than ``split_margin``).
    ``s`` then starts a new object and ``k``, seen elsewhere the frame before, stays
    unmatched; ``track_segments`` gives the part of ``x``'s previous-frame pixels to the new
    object and ``split_merged_objects`` carries it back to frame 0. An object not seen in the
    previous frame may have been inside ``x``'s segment there, so its pairs are left alone, as
    are segments below ``split_min_px`` (``split_merged_objects`` would not split them).

    Args:
        assignment: segment id -> object id; cost: (S, K) costs (rows ``segment_ids``,
            columns ``known_ids``); segments: this frame's segment features by (untracked)
            segment id; seen_last_frame: ids seen in the previous frame; previous_labels:
            (H, W) int tracked ids of the previous frame; previous_frame: its (H, W, 3) world
            points (m), (H, W, 3) uint8 colours and (H, W) depth (m, 0 = no reading; None =
            all valid); change: called at most once (only when a pair is a candidate) with
            ``compared``, an (H, W) bool mask of the previous frame's pixels needed: frame
            t-1's pixels followed into this frame's segments (``follow_previous_frame``: a
            ``FrameChange`` of frame t-1's shape whose ``previous_label`` holds this frame's
            segment ids).

    Returns:
        The new segment -> object assignment, and per segment unmatched here (piece segment
        id, object ``x``, (M,) flat previous-frame pixels of the part).
    """
    row_of = {segment_id: row for row, segment_id in enumerate(segment_ids)}
    column_of = {object_id: column for column, object_id in enumerate(known_ids)}
    pieces = {
        segment_id: float(cost[row_of[segment_id], column_of[object_id]])
        for segment_id, object_id in assignment.items()
        if object_id in seen_last_frame
        and cost[row_of[segment_id], column_of[object_id]] > config.max_match_cost
        and segments[segment_id].pixels.size >= config.split_min_px
    }
    if not pieces:
        return assignment, []
    depth = previous_frame[2]
    flat = previous_labels.reshape(-1)
    with_depth = np.ones(flat.size, dtype=bool) if depth is None else depth.reshape(-1) > 0
    order, ids, starts = kernels.labelled_order(flat, with_depth)
    ends = np.append(starts[1:], order.size)
    # (object, its segment, its previous-frame pixels with depth, the pieces it may have lost)
    splits = []
    for segment_id, object_id in sorted(assignment.items()):
        where = int(np.searchsorted(ids, object_id))
        if where == ids.size or ids[where] != object_id:
            continue  # not labelled in the previous frame
        pixels = order[starts[where] : ends[where]]
        least = max(config.split_min_share * pixels.size, config.split_min_px)
        if pixels.size < 2 * least:
            continue  # no part and rest of the size
        candidates = [(piece, pair) for piece, pair in pieces.items() if piece != segment_id]
        if candidates:
            splits.append((object_id, segments[segment_id], pixels, candidates))
    if not splits:
        return assignment, []
    # Only the pixels of the objects that may have lost a part are followed into this frame.
    compared = np.zeros(flat.size, dtype=bool)
    for _, _, pixels, _ in splits:
        compared[pixels] = True
    following = change(compared=compared.reshape(previous_labels.shape))
    state, label_in_t = following.state.reshape(-1), following.previous_label.reshape(-1)
    best: dict[int, tuple[float, int, np.ndarray]] = {}  # piece -> (gain, object, part)
    for object_id, x_t, pixels, candidates in splits:
        gone = state[pixels] == ARRIVED
        seen_in_place = state[pixels] == UNCHANGED
        whole = None
        for piece, pair in candidates:
            parts = _split_parts(
                pixels, seen_in_place & (label_in_t[pixels] == piece), gone, config
            )
            for part in parts:
                # Each side of the split explains this frame better than the pairing it
                # replaces: the piece the part than the object it was paired with (checked
                # first: it fails most often), the object's segment its own pixels without the
                # part than with it.
                part_cost = pair_cost(
                    segments[piece], _pixel_features(pixels[part], *previous_frame), config
                )
                if part_cost >= pair:
                    continue
                if whole is None:
                    whole = pair_cost(x_t, _pixel_features(pixels, *previous_frame), config)
                rest_cost = pair_cost(x_t, _pixel_features(pixels[~part], *previous_frame), config)
                gain = whole + pair - rest_cost - part_cost
                if rest_cost >= whole or gain <= config.split_margin:
                    continue
                if piece not in best or gain > best[piece][0]:
                    best[piece] = (gain, object_id, pixels[part])
    result = {s: o for s, o in assignment.items() if s not in best}
    return result, [(piece, object_id, part) for piece, (_, object_id, part) in best.items()]


def _split_parts(
    pixels: np.ndarray, seen_as_new: np.ndarray, gone: np.ndarray, config: TrackingConfig
) -> list[np.ndarray]:
    """The candidate parts ((N,) bool) of an object's (N,) previous-frame pixels with depth
    that a later object ``z`` may take (``split_merged_objects``): those seen as ``z`` in place
    or gone, and those seen as ``z``, each kept when it and the rest hold at least
    ``split_min_share`` of the pixels and ``split_min_px``."""
    least = max(config.split_min_share * pixels.size, config.split_min_px)
    return [
        part
        for part in (seen_as_new | gone, seen_as_new)
        if least <= np.count_nonzero(part) <= pixels.size - least
    ]


def _split_gain(
    pixels: np.ndarray,
    parts: list[np.ndarray],
    x_t: SegmentFeatures,
    z_t: SegmentFeatures,
    previous_frame: tuple[np.ndarray, np.ndarray, np.ndarray | None],
    config: TrackingConfig,
) -> tuple[float, np.ndarray]:
    """``split_merged_objects``' test of the candidate ``parts`` (non-empty, ``_split_parts``)
    of an object ``x``'s (N,) previous-frame pixels with depth, given its segment ``x_t`` and
    the new object's ``z_t`` in frame t and the previous frame's (points, colours, depth):
    the best (gain, part's pixels), the gain being ``pair_cost(x_t, all) + max_match_cost``
    (``z`` as a new object) less ``pair_cost(x_t, rest) + pair_cost(z_t, part)``."""
    unsplit = (
        pair_cost(x_t, _pixel_features(pixels, *previous_frame), config) + config.max_match_cost
    )
    best = None
    for part in parts:
        split = pair_cost(x_t, _pixel_features(pixels[~part], *previous_frame), config) + (
            pair_cost(z_t, _pixel_features(pixels[part], *previous_frame), config)
        )
        if best is None or unsplit - split > best[0]:
            best = (unsplit - split, pixels[part])
    return best


def _gated_assignment(cost: np.ndarray, gate: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the pairs of the cheapest assignment of a (S, K) cost matrix in which
    each row may instead stay unmatched at ``gate`` and each column at no cost: no pair dearer
    than ``gate`` is used, and a pair is left out only when that lowers the total (the gate is
    part of the optimisation rather than applied to its result)."""
    n_rows, n_cols = cost.shape
    augmented = np.full((n_rows + n_cols, n_cols + n_rows), _FORBIDDEN)
    augmented[:n_rows, :n_cols] = np.where(cost <= gate, cost, _FORBIDDEN)
    augmented[:n_rows, n_cols:][np.eye(n_rows, dtype=bool)] = gate
    augmented[n_rows:, :n_cols][np.eye(n_cols, dtype=bool)] = 0.0
    augmented[n_rows:, n_cols:] = 0.0
    rows, cols = linear_sum_assignment(augmented)
    matched = (rows < n_rows) & (cols < n_cols)
    return rows[matched], cols[matched]


def prefer_larger_pieces(
    assignment: dict[int, int],
    cost: np.ndarray,
    segment_ids: list[int],
    known_ids: list[int],
    segments: dict[int, SegmentFeatures],
    config: TrackingConfig,
    extent_of: Callable[[int, int], float] | None = None,
) -> dict[int, int]:
    """Give an object's id to the larger of two pieces it was split into.

    When the segmentation splits an object (usually one that was pushed and shows new faces),
    the assignment may match its id to a small piece that resembles the earlier view in size
    and place and leave the larger piece to start a new object. A segment left unmatched whose
    cheapest known object costs at most ``elimination_cost`` (what the assignment's second
    stage accepts) and at most ``piece_cost_margin`` more than the segment matched to that
    object, whose centroid is within ``piece_gap_extent_share`` times the object's size
    (``extent_of``: at least its own recent sightings' and, if the piece is part of it, the
    piece's) of that segment's (``piece_max_gap_m`` when ``piece_gap_relative`` is off
    or no size is given) and whose visible area is ``piece_area_ratio`` times larger takes the
    object's id; the smaller piece becomes a new object. The cost and gap tests are relative
    (docs/DESIGN_NOTES.md, "The larger piece keeps the id"): a pushed object's pieces may all
    cost more than an absolute gate, while a segment that holds a sliver of the object and
    mostly something else costs clearly more than the sliver; the pieces of a large box lie
    farther apart than those of a can. Unmatched segments are visited by decreasing area.
    Returns the new segment -> object assignment.

    Args:
        assignment: segment id -> object id; cost: (S, K) costs (rows ``segment_ids``,
            columns ``known_ids``); segments: the frame's segment features; extent_of: (object
            id, piece's segment id) -> the object's size (m; ``track_segments`` gives the
            largest ``extent_m`` of its recent sightings and of the piece: a recent sighting
            may show only a strip of it), called only for a candidate that passed the other
            tests, or None.
    """
    result = dict(assignment)
    segment_of = {object_id: segment_id for segment_id, object_id in result.items()}
    row_of = {segment_id: row for row, segment_id in enumerate(segment_ids)}
    rows = [r for r, s in enumerate(segment_ids) if s not in result]
    for row in sorted(rows, key=lambda r: -segments[segment_ids[r]].area):
        column = int(np.argmin(cost[row]))
        if cost[row, column] > config.elimination_cost:
            continue
        object_id, piece = known_ids[column], segment_ids[row]
        matched = segment_of.get(object_id)
        if (
            matched is None
            or segments[piece].area < config.piece_area_ratio * segments[matched].area
        ):
            continue
        # Relative, not absolute: the larger piece resembles the object almost as well as the
        # piece holding the id (a pushed object's pieces may all cost more than
        # ``piece_max_cost``; a larger segment that only holds a sliver of the object costs
        # clearly more than the sliver that took its id).
        if cost[row, column] > cost[row_of[matched], column] + config.piece_cost_margin:
            continue
        gap = float(np.linalg.norm(segments[piece].centroid - segments[matched].centroid))
        # Relative to the object's own size: two pieces of one object lie within it, whatever
        # its size (a large box's larger piece may lie more than 10 cm from the piece holding
        # its id, two 5 cm objects 8 cm apart are not one).
        if extent_of is not None and config.piece_gap_relative:
            if gap > config.piece_gap_extent_share * extent_of(object_id, piece):
                continue
        elif gap > config.piece_max_gap_m:
            continue
        del result[matched]
        result[piece] = object_id
        segment_of[object_id] = piece
    return result


def prefer_larger_objects(
    assignment: dict[int, int],
    cost: np.ndarray,
    segment_ids: list[int],
    known_ids: list[int],
    latest: dict[int, SegmentFeatures],
    config: TrackingConfig,
) -> dict[int, int]:
    """Give a segment the id of the larger of two known pieces of one object.

    The converse of ``prefer_larger_pieces``: an object split into two pieces in an earlier
    frame and whole again now matches both pieces' ids almost equally, and the assignment may
    pick the smaller piece's. A known object left unmatched whose cheapest segment costs at
    most ``piece_max_cost`` and at most ``piece_cost_margin`` more than the object that segment
    was matched to, whose reference sighting was larger than that object's and within
    ``piece_max_gap_m`` of it, takes the segment. Unmatched objects are visited by decreasing
    area. Returns the new segment -> object assignment.

    Args:
        assignment: segment id -> object id; cost: (S, K) costs (rows ``segment_ids``,
            columns ``known_ids``); latest: each known object's reference sighting
            (``track_segments`` gives its largest of the last ``max_sightings``).
    """
    result = dict(assignment)
    matched_objects = set(result.values())
    columns = [c for c, o in enumerate(known_ids) if o not in matched_objects]
    column_of = {o: c for c, o in enumerate(known_ids)}
    for column in sorted(columns, key=lambda c: -latest[known_ids[c]].area):
        if cost.shape[0] == 0:
            break
        row = int(np.argmin(cost[:, column]))
        candidate, segment_id = known_ids[column], segment_ids[row]
        current = result.get(segment_id)
        if current is None or cost[row, column] > config.piece_max_cost:
            continue
        if cost[row, column] > cost[row, column_of[current]] + config.piece_cost_margin:
            continue
        if latest[candidate].area < config.piece_area_ratio * latest[current].area:
            continue
        gap = np.linalg.norm(latest[candidate].centroid - latest[current].centroid)
        if gap > config.piece_max_gap_m:
            continue
        result[segment_id] = candidate
    return result


def _touching_alike(
    first: SegmentFeatures,
    second: SegmentFeatures,
    width: int,
    flat_points: np.ndarray,
    valid: np.ndarray | None,
    config: TrackingConfig,
) -> bool:
    """Whether two segments of one frame may be pieces of one object: colours within
    ``merge_max_colour`` and at least ``merge_min_contact_px`` touching pixel pairs
    (``contact_pixels`` on the frame's (H*W, 3) world points, image ``width`` pixels wide, and
    its (H*W,) depth validity or None)."""
    if colour_distance(first, second) > config.merge_max_colour:
        return False
    contact = contact_pixels(
        first.pixels, second.pixels, width, flat_points, config.merge_contact_gap_m, valid
    )
    return contact >= config.merge_min_contact_px


def _free_for(
    matched: int | None,
    object_id: int,
    row_cost: np.ndarray,
    column_of: dict[int, int],
    holders: frozenset[int] = frozenset(),
) -> bool:
    """Whether a segment matched to ``matched`` (None: unmatched) may become a piece of
    ``object_id``: it is unmatched, matched to that object, or matched to another object that
    it resembles less (a leftover pairing of the assignment's second stage) and that is not
    one of ``holders`` (objects whose segments are not given up: seen the frame before, with
    ``merge_keeps_seen_objects``)."""
    if matched is None or matched == object_id:
        return True
    if matched in holders:
        return False
    return bool(row_cost[column_of[object_id]] < row_cost[column_of[matched]])


def merge_split_pieces(
    assignment: dict[int, int],
    cost: np.ndarray,
    segment_ids: list[int],
    known_ids: list[int],
    segments: dict[int, SegmentFeatures],
    sightings: dict[int, list[SegmentFeatures]],
    points: np.ndarray,
    config: TrackingConfig,
    depth_m: np.ndarray | None = None,
    seen_last_frame: set[int] | None = None,
) -> tuple[dict[int, int], dict[int, int]]:
    """Join pieces of this frame that together are one known object.

    An object the segmentation splits into comparable pieces (a pushed object showing new
    faces) hands its id to one of them almost at random, since either resembles the earlier
    view about as well, and the other piece starts a new object; the metric's best segment is
    then often the other piece, and neither piece may reach the F-measure the whole would.
    For each known object, among its ``merge_candidates`` cheapest segments that cost at most
    ``piece_max_cost`` and are unmatched, matched to that object or matched to another object
    they resemble less (a leftover pairing of the assignment's second stage, which loses the
    segment if it is joined; docs/DESIGN_NOTES.md, "Objects split in an earlier frame are
    joined"), two that touch (``merge_min_contact_px`` neighbouring pixel pairs whose points are
    within ``merge_contact_gap_m``: surfaces that meet, not one in front of the other) and whose
    colours are within ``merge_max_colour`` are joined when the union's cost (lowest over the
    object's sightings) is below both pieces' by more than ``merge_margin``; the cheapest such
    union wins, and joining repeats with the union as a piece (an object cut in three).

    Args:
        assignment: segment id -> object id; cost: (S, K) costs (rows ``segment_ids``,
            columns ``known_ids``); segments: the frame's segment features, updated in place
            (the kept segment's become the union's, absorbed segments are removed);
            sightings: each known object's sightings; points: the frame's (H, W, 3) world
            points (m); depth_m: its (H, W) depth (m, 0 = no reading; None = all valid);
            seen_last_frame: ids seen in the previous frame (with
            ``merge_keeps_seen_objects``, a segment matched to one of them, other than the
            object joined, is no candidate piece: the object is there, and the segment is
            it; None: no such object).

    Returns:
        The new segment -> object assignment and the joins {absorbed segment: kept segment}.
    """
    result = dict(assignment)
    holders = frozenset(seen_last_frame or ()) if config.merge_keeps_seen_objects else frozenset()
    joins: dict[int, int] = {}
    column_of = {o: c for c, o in enumerate(known_ids)}
    width = points.shape[1]
    flat_points = points.reshape(-1, 3)
    valid = None if depth_m is None else depth_m.reshape(-1) > 0
    for column, object_id in enumerate(known_ids):
        # Cost of each candidate row to this object (a joined row costs what its union does).
        row_cost = {
            int(row): float(cost[row, column])
            for row in np.argsort(cost[:, column])[: config.merge_candidates]
            if cost[row, column] <= config.piece_max_cost
            and segment_ids[row] in segments
            and _free_for(result.get(segment_ids[row]), object_id, cost[row], column_of, holders)
        }
        while len(row_cost) >= 2:
            best = None
            for first, second in combinations(sorted(row_cost, key=row_cost.get), 2):
                a, b = segments[segment_ids[first]], segments[segment_ids[second]]
                if not _touching_alike(a, b, width, flat_points, valid, config):
                    continue
                union = merged_features(a, b)
                union_cost = min(pair_cost(union, seen, config) for seen in sightings[object_id])
                if union_cost >= min(row_cost[first], row_cost[second]) - config.merge_margin:
                    continue
                if best is None or union_cost < best[0]:
                    best = (union_cost, first, second, union)
            if best is None:
                break
            union_cost, first, second, union = best
            kept, absorbed = segment_ids[first], segment_ids[second]
            segments[kept] = union
            del segments[absorbed]
            result.pop(absorbed, None)
            result[kept] = object_id
            joins[absorbed] = kept
            del row_cost[second]
            row_cost[first] = union_cost
    return result, joins


def merge_split_objects(
    assignment: dict[int, int],
    segments: dict[int, SegmentFeatures],
    sightings: dict[int, list[SegmentFeatures]],
    sighting_frames: dict[int, list[int]],
    frames_points: list[np.ndarray],
    frames_depth: list[np.ndarray | None],
    config: TrackingConfig,
) -> list[tuple[int, int]]:
    """Known objects that were pieces of one object in an earlier frame, and that this frame
    sees whole: pairs (kept id, absorbed id) to join in every frame.

    The converse of ``merge_split_pieces``, backwards in time: an object the segmentation
    split in an earlier frame (often frame 0, before any push) gave each piece an id, and when
    a later frame shows it whole its segment takes one of the ids almost at random, since each
    piece resembles part of it; the other id is lost for good. For a segment matched to object
    ``a`` and a known object ``b`` left unmatched in this frame, seen in a frame where ``a``
    was seen too, touching it there (as in ``merge_split_pieces``) and of similar colour
    (``merge_max_colour``): when the union of the two sightings resembles the segment better
    than ``a``'s own best sighting by more than ``object_merge_margin``, ``b`` joins ``a``.

    Args:
        assignment: segment id -> object id of this frame; segments: its segment features;
            sightings, sighting_frames: each object's recent sightings and the frame index of
            each (updated in place: ``a``'s sighting in the shared frame becomes the union,
            ``b`` is removed); frames_points, frames_depth: every frame's (H, W, 3) world points
            (m) and (H, W) depth (m, 0 = no reading; None = all valid).
    """
    joins: list[tuple[int, int]] = []
    matched = set(assignment.values())
    valid_of_frame: dict[int, np.ndarray | None] = {}  # each frame's depth validity, once
    for segment_id, kept in sorted(assignment.items()):
        if kept not in sightings:
            continue
        segment = segments[segment_id]
        own = None  # the segment's cost to its object, when a candidate needs it
        best = None
        for other in sorted(sightings):
            if other == kept or other in matched:
                continue
            for frame in set(sighting_frames[kept]) & set(sighting_frames[other]):
                a = sightings[kept][sighting_frames[kept].index(frame)]
                b = sightings[other][sighting_frames[other].index(frame)]
                if colour_distance(a, b) > config.merge_max_colour:
                    continue  # _touching_alike's first test, before any per-pixel work
                if frame not in valid_of_frame:
                    depth = frames_depth[frame]
                    valid_of_frame[frame] = None if depth is None else depth.reshape(-1) > 0
                points = frames_points[frame]
                if not _touching_alike(
                    a, b, points.shape[1], points.reshape(-1, 3), valid_of_frame[frame], config
                ):
                    continue
                if own is None:
                    own = min(pair_cost(segment, seen, config) for seen in sightings[kept])
                union = merged_features(a, b)
                union_cost = pair_cost(segment, union, config)
                if union_cost >= own - config.object_merge_margin:
                    continue
                if best is None or union_cost < best[0]:
                    best = (union_cost, other, frame, union)
        if best is None:
            continue
        _, other, frame, union = best
        sightings[kept][sighting_frames[kept].index(frame)] = union
        del sightings[other], sighting_frames[other]
        matched.add(other)
        joins.append((kept, other))
    return joins


def split_merged_segments(
    assignment: dict[int, int],
    segments: dict[int, SegmentFeatures],
    sightings: dict[int, list[SegmentFeatures]],
    shape: tuple[int, int],
    points: np.ndarray,
    rgb: np.ndarray,
    depth_m: np.ndarray | None,
    config: TrackingConfig,
) -> dict[int, int]:
    """Split a segment that holds a known object left unmatched in this frame and the object it
    was matched to.

    A push often leaves two objects touching, and the segmentation may then give them one
    segment for a frame: the segment takes one object's id and the other object finds no segment
    (most of the pairs lost for lack of a segment were such unions: docs/DESIGN_NOTES.md,
    "Objects pushed into one segment are split again"). For a known object ``b`` left unmatched
    and a segment matched to object ``a``, each pixel of the segment whose colour is
    ``segment_split_ratio`` times likelier under ``b``'s colour histogram than under ``a``'s
    (their latest sightings) votes for ``b``; the largest 8-connected region of such pixels (at
    least ``segment_split_min_px``) is the candidate part of ``b``. The split is made when that
    part costs at most ``max_match_cost`` as ``b`` and the rest costs less as ``a`` than the
    whole segment did, by more than ``segment_split_margin`` (a real union resembles neither
    object as well as its parts do). With ``segment_split_leftover_gate`` (opt-in) the part may
    cost up to ``elimination_cost``, the gate of the second stage, which pairs leftover objects
    with leftover segments (a pushed object costs more than ``max_match_cost`` to its earlier
    view, and after both stages ``b`` is a leftover object), when the split also passes
    ``split_merged_objects``' test: the rest's and the part's costs together are below the
    whole's plus ``max_match_cost`` (the part as a new object). The part becomes a new segment
    (``segments`` updated in place) assigned to ``b``; of the candidate segments for one
    object, the one whose part costs least. Returns the new segment -> object assignment.

    Args:
        shape: (H, W) of the frame; points: (H, W, 3) world points (m); rgb: (H, W, 3) uint8;
            depth_m: (H, W) depth (m, 0 = no reading) or None (all valid).
    """
    from scipy.ndimage import label as connected_regions

    result = dict(assignment)
    matched = set(result.values())
    width = shape[1]
    codes_of: dict[int, np.ndarray] = {}  # colour codes of each segment's pixels, once
    for object_id in sorted(sightings):
        if object_id in matched:
            continue
        known = sightings[object_id]
        b_histogram = known[-1].histogram
        best = None
        for segment_id, kept in sorted(result.items()):
            if kept not in sightings:
                continue
            segment = segments[segment_id]
            likelier = b_histogram > config.segment_split_ratio * sightings[kept][-1].histogram
            # The votes counted from the segment's histogram first (the same count up to
            # rounding): most pairs stop here, before any per-pixel work.
            votes_from_histogram = segment.histogram @ likelier * segment.pixels.size
            if votes_from_histogram < config.segment_split_min_px - 0.5:
                continue
            if segment_id not in codes_of:
                codes_of[segment_id] = _colour_codes(rgb.reshape(-1, 3)[segment.pixels])
            votes = likelier[codes_of[segment_id]]
            if np.count_nonzero(votes) < config.segment_split_min_px:
                continue
            rows, cols = np.divmod(segment.pixels[votes], width)
            top, left = rows.min(), cols.min()
            mask = np.zeros((rows.max() - top + 1, cols.max() - left + 1), dtype=bool)
            mask[rows - top, cols - left] = True
            regions, _ = connected_regions(mask, structure=np.ones((3, 3), dtype=bool))
            region_of_vote = regions[rows - top, cols - left]
            largest = int(np.argmax(np.bincount(region_of_vote)[1:])) + 1
            part = segment.pixels[votes][region_of_vote == largest]
            if part.size < config.segment_split_min_px or part.size >= segment.pixels.size:
                continue
            part_features = _pixel_features(part, points, rgb, depth_m)
            part_cost = min(pair_cost(part_features, seen, config) for seen in known)
            if config.segment_split_leftover_gate:
                gate = config.elimination_cost
            else:
                gate = config.max_match_cost
            if part_cost > gate or (best is not None and part_cost >= best[0]):
                continue
            rest = np.setdiff1d(segment.pixels, part, assume_unique=True)
            rest_features = _pixel_features(rest, points, rgb, depth_m)
            whole_cost = min(pair_cost(segment, seen, config) for seen in sightings[kept])
            rest_cost = min(pair_cost(rest_features, seen, config) for seen in sightings[kept])
            if rest_cost >= whole_cost - config.segment_split_margin:
                continue
            if (
                config.segment_split_leftover_gate
                and rest_cost + part_cost
                >= whole_cost + config.max_match_cost - config.segment_split_margin
            ):
                continue
            if best is None or part_cost < best[0]:
                best = (part_cost, segment_id, part_features, rest_features)
        if best is None:
            continue
        _, segment_id, part_features, rest_features = best
        new_segment = max(segments) + 1
        segments[segment_id] = rest_features
        segments[new_segment] = part_features
        codes_of.pop(segment_id, None)
        result[new_segment] = object_id
        matched.add(object_id)
    return result


def track_segments(
    frames_labels: list[np.ndarray],
    frames_points: list[np.ndarray],
    frames_rgb: list[np.ndarray],
    config: TrackingConfig | None = None,
    frames_depth: list[np.ndarray] | None = None,
    follow: Callable[..., FrameChange] | None = None,
) -> list[np.ndarray]:
    """Relabel per-frame segments (H, W) int so that one object keeps one id in every frame.

    Frame 0's segments get ids 1..k in their own order; later segments take the id of the known
    object they match (``assign_segments`` on ``match_costs``, each object's cost the lowest
    over its last ``max_sightings`` sightings), or the next unused id; objects found to be
    pieces of one (``merge_split_objects``) end with one id in every frame. Returns new (H, W)
    int32 label images.

    Args:
        frames_labels: per frame, (H, W) int segment labels (0 = none); frames_points: (H, W, 3)
            world points (m); frames_rgb: (H, W, 3) uint8; frames_depth: (H, W) depth (m, 0 =
            no reading), or None (all valid); follow: (t, frame t's (H, W) segment labels,
            keyword ``compared``: (H, W) bool pixels of frame t-1 to follow) -> frame t-1's
            pixels followed into frame t (``follow_previous_frame`` with the frames' cameras),
            for ``pushed_out_guard``; None: that guard does not act.
    """
    config = config or TrackingConfig()
    tracked: list[np.ndarray] = []
    sightings: dict[int, list[SegmentFeatures]] = {}  # oldest first
    sighting_frames: dict[int, list[int]] = {}  # the frame index of each sighting
    joined: dict[int, int] = {}  # absorbed id -> the id it joined (merge_split_objects)
    next_id = 1
    depths = frames_depth if frames_depth is not None else [None] * len(frames_labels)
    for frame_index, (labels, points, rgb, depth) in enumerate(
        zip(frames_labels, frames_points, frames_rgb, depths, strict=True)
    ):
        if not sightings and frame_index == len(frames_labels) - 1:
            # No object known and no frame after this one (a single-frame scene): nothing is
            # matched, so the segments take ids in label order and their features, which only
            # matching reads, are not computed.
            tracked.append(numbered_in_order(labels, next_id))
            continue
        segments = segment_features(labels, points, rgb, depth)
        assignment: dict[int, int] = {}
        pushed_out: list[tuple[int, int, np.ndarray]] = []
        if sightings and segments:
            segment_ids, known_ids = sorted(segments), sorted(sightings)
            cost = np.full((len(segment_ids), len(known_ids)), np.inf)
            for back in range(1, max(len(seen) for seen in sightings.values()) + 1):
                # The back-th latest sighting of every object seen at least back times.
                layer = {o: seen[-back] for o, seen in sightings.items() if len(seen) >= back}
                _, layer_ids, layer_cost = match_costs(layer, segments, labels.size, config)
                columns = np.searchsorted(known_ids, layer_ids)
                cost[:, columns] = np.minimum(cost[:, columns], layer_cost)
            seen_last_frame = {o for o, f in sighting_frames.items() if f[-1] == frame_index - 1}
            refused = None
            if config.separated_piece_guard and tracked:
                refused = partial(
                    _separated_rows,
                    segments=segments,
                    segment_ids=segment_ids,
                    known_ids=known_ids,
                    seen_last_frame=seen_last_frame,
                    previous_labels=tracked[-1],
                    previous_points=frames_points[frame_index - 1],
                    points=points,
                    previous_rgb=frames_rgb[frame_index - 1],
                    rgb=rgb,
                    depth_m=depth,
                    previous_depth_m=depths[frame_index - 1],
                    config=config,
                )
            for row, col in assign_segments(
                cost,
                config.max_match_cost,
                config.elimination_cost,
                config.gated_elimination,
                refused,
            ):
                assignment[segment_ids[row]] = known_ids[col]
            if config.pushed_out_guard and tracked and follow is not None:
                assignment, pushed_out = pushed_out_pieces(
                    assignment,
                    cost,
                    segment_ids,
                    known_ids,
                    segments,
                    seen_last_frame,
                    tracked[-1],
                    (
                        frames_points[frame_index - 1],
                        frames_rgb[frame_index - 1],
                        depths[frame_index - 1],
                    ),
                    partial(follow, frame_index, labels),
                    config,
                )
            if config.larger_piece_takes_id:
                extent_of = partial(
                    _object_size,
                    sightings=sightings,
                    sighting_frames=sighting_frames,
                    frames_points=frames_points,
                    frames_depth=depths,
                    segments=segments,
                    frame=frame_index,
                )
                assignment = prefer_larger_pieces(
                    assignment, cost, segment_ids, known_ids, segments, config, extent_of
                )
            if config.larger_object_takes_segment:
                # Each object's largest recent view: its latest may be half hidden.
                latest = {o: max(seen, key=lambda f: f.area) for o, seen in sightings.items()}
                assignment = prefer_larger_objects(
                    assignment, cost, segment_ids, known_ids, latest, config
                )
            if config.merge_split_pieces:
                assignment, _ = merge_split_pieces(
                    assignment,
                    cost,
                    segment_ids,
                    known_ids,
                    segments,
                    sightings,
                    points,
                    config,
                    depth,
                    seen_last_frame,
                )
            if config.merge_split_objects:
                for kept, absorbed in merge_split_objects(
                    assignment,
                    segments,
                    sightings,
                    sighting_frames,
                    frames_points,
                    depths,
                    config,
                ):
                    joined[absorbed] = kept
            if config.split_merged_segments:
                assignment = split_merged_segments(
                    assignment, segments, sightings, labels.shape, points, rgb, depth, config
                )
        relabelled = np.zeros(labels.size, dtype=np.int32)
        started: dict[int, int] = {}  # segment id -> the new object it starts
        for segment_id in sorted(segments):
            object_id = assignment.get(segment_id)
            if object_id is None:
                object_id = started[segment_id] = next_id
                next_id += 1
            next_id = max(next_id, object_id + 1)
            relabelled[segments[segment_id].pixels] = object_id
            seen = sightings.setdefault(object_id, [])
            seen.append(segments[segment_id])
            del seen[: -config.max_sightings]
            frames_seen = sighting_frames.setdefault(object_id, [])
            frames_seen.append(frame_index)
            del frames_seen[: -config.max_sightings]
        tracked.append(relabelled.reshape(labels.shape))
        for piece, object_id, part in pushed_out:
            # The part of the previous frame's object the piece was pushed out of becomes the
            # piece's new object there (``split_merged_objects`` carries it back to frame 0).
            if piece in started:
                valid = (
                    np.ones(labels.size, dtype=bool)
                    if depths[frame_index - 1] is None
                    else (depths[frame_index - 1].reshape(-1) > 0)
                )
                tracked[-2] = _relabel_part(tracked[-2], object_id, started[piece], part, valid)
    if joined:
        # Every frame shows a joined object under the id it finally joined (joins may chain).
        final = np.arange(next_id, dtype=np.int32)
        for absorbed in joined:
            target = joined[absorbed]
            while target in joined:
                target = joined[target]
            final[absorbed] = target
        tracked = [final[labels] for labels in tracked]
    return tracked


def numbered_in_order(labels: np.ndarray, first: int = 1) -> np.ndarray:
    """(H, W) int32: the segments (labels k >= 1) of a (H, W) int label image renumbered
    ``first``, ``first + 1``, ... in increasing label, 0 elsewhere: what ``track_segments``
    gives a frame with no known object to match (each segment a new object, in label
    order)."""
    flat = labels.reshape(-1)
    if flat.size and flat.min() < 0:
        flat = np.maximum(flat, 0)  # negative labels are no segment either
    sizes = np.bincount(flat, minlength=1)
    sizes[0] = 0
    present = np.flatnonzero(sizes)
    lookup = np.zeros(len(sizes), dtype=np.int32)
    lookup[present] = np.arange(first, first + len(present), dtype=np.int32)
    return lookup[flat].reshape(labels.shape)


def _object_size(
    object_id: int,
    piece: int,
    *,
    sightings: dict[int, list[SegmentFeatures]],
    sighting_frames: dict[int, list[int]],
    frames_points: list[np.ndarray],
    frames_depth: list[np.ndarray | None],
    segments: dict[int, SegmentFeatures],
    frame: int,
) -> float:
    """A known object's size (m) for ``prefer_larger_pieces``: the largest ``extent_m`` of its
    recent sightings (each in its own frame of ``frames_points`` / ``frames_depth``) and of the
    segment ``piece`` of frame ``frame`` (``segments``). A recent sighting may show only a
    strip of the object, so the larger piece, if it is part of it, bounds its size too."""
    sizes = [
        extent_m(seen.pixels, frames_points[seen_in], frames_depth[seen_in])
        for seen, seen_in in zip(sightings[object_id], sighting_frames[object_id], strict=True)
    ]
    piece_size = extent_m(segments[piece].pixels, frames_points[frame], frames_depth[frame])
    return max(*sizes, piece_size)


def split_merged_objects(
    tracked: list[np.ndarray],
    frames_points: list[np.ndarray],
    frames_rgb: list[np.ndarray],
    frames_depth: list[np.ndarray],
    frames_K: list[np.ndarray],
    frames_world_from_camera: list[np.ndarray],
    config: PerceptionConfig,
) -> list[np.ndarray]:
    """Split, in earlier frames, an object that a later frame shows to be two.

    The converse of ``merge_split_objects``: frame 0 (before any push) often gives two
    touching objects one segment, and when a push separates them the later frame's tracker
    keeps the id for one and starts a new object for the other, whose frame-0 pixels then stay
    under the wrong id for good. For an object ``z`` first seen in frame t and an object ``x``
    seen in frames t-1 and t, the pixels of ``x`` in frame t-1 are followed into frame t
    (``temporal.compare_frames`` with the frames swapped): those now seen as ``z`` in place,
    or also those whose surface is gone (frame t sees through them), are the candidate part
    ``g`` of ``z``. The split is made when both parts hold at least ``split_min_share`` of
    ``x``'s pixels with depth (and ``split_min_px``), and it explains frame t better:
    ``pair_cost(x_t, rest) + pair_cost(z_t, g)`` is below ``pair_cost(x_t, x_{t-1}) +
    max_match_cost`` (``z`` as a new object) by more than ``split_margin``. Frames run from the
    last back to the first, so a split carries back to frame 0 (``z`` is then first seen in
    t-1). Pixels of ``x`` without depth go to the part of their nearest pixel with depth.

    Args:
        tracked: per frame, (H, W) int tracked labels (``track_segments``), not modified;
            frames_points: (H, W, 3) world points (m); frames_rgb: (H, W, 3) uint8;
            frames_depth: (H, W) depth (m, 0 = no reading); frames_K: (3, 3) intrinsics (px);
            frames_world_from_camera: (4, 4) camera poses (world from OpenCV camera, m).

    Returns:
        (H, W) int32 label images (new arrays for the frames changed).
    """
    tracking = config.tracking
    result = [np.asarray(labels, dtype=np.int32) for labels in tracked]  # copied on change
    if len(result) < 2:
        return result  # no later frame to show a split
    # Ids present in each frame (np.unique over whole images would cost more than the rest).
    sizes = [np.bincount(labels.reshape(-1)) for labels in result]
    present = [{int(i) for i in np.flatnonzero(size)} - {0} for size in sizes]
    for t in range(len(result) - 1, 0, -1):
        new_ids = sorted(
            i for i in present[t].difference(*present[:t]) if sizes[t][i] >= tracking.split_min_px
        )
        if not new_ids:
            continue
        previous_ids = sorted(present[t - 1] & present[t])
        change = follow_previous_frame(
            t,
            result[t],
            frames_points=frames_points,
            frames_depth=frames_depth,
            frames_K=frames_K,
            frames_world_from_camera=frames_world_from_camera,
            config=config,
        )
        state, label_in_t = change.state.reshape(-1), change.previous_label.reshape(-1)
        segments_t = segment_features(result[t], frames_points[t], frames_rgb[t], frames_depth[t])
        previous_flat = result[t - 1].reshape(-1)
        with_depth = frames_depth[t - 1].reshape(-1) > 0
        best: tuple[float, int, int, np.ndarray] | None = None
        previous_frame = (frames_points[t - 1], frames_rgb[t - 1], frames_depth[t - 1])
        for new_id in new_ids:
            z_t = segments_t[new_id]
            for object_id in previous_ids:
                pixels = np.flatnonzero((previous_flat == object_id) & with_depth)
                seen_as_new = (state[pixels] == UNCHANGED) & (label_in_t[pixels] == new_id)
                parts = _split_parts(pixels, seen_as_new, state[pixels] == ARRIVED, tracking)
                if not parts:
                    continue
                gain, part = _split_gain(
                    pixels, parts, segments_t[object_id], z_t, previous_frame, tracking
                )
                if gain > tracking.split_margin and (best is None or gain > best[0]):
                    best = (gain, object_id, new_id, part)
            if best is not None:
                _, object_id, new_id, part = best
                result[t - 1] = _relabel_part(result[t - 1], object_id, new_id, part, with_depth)
                present[t - 1].add(new_id)
                sizes[t - 1] = np.bincount(result[t - 1].reshape(-1))
                previous_flat = result[t - 1].reshape(-1)
                best = None
    return result


def follow_previous_frame(
    t: int,
    labels_t: np.ndarray,
    *,
    frames_points: list[np.ndarray],
    frames_depth: list[np.ndarray],
    frames_K: list[np.ndarray],
    frames_world_from_camera: list[np.ndarray],
    config: PerceptionConfig,
    compared: np.ndarray | None = None,
) -> FrameChange:
    """Frame t-1's pixels followed into frame t (``temporal.compare_frames`` with the frames
    swapped): per pixel of frame t-1, ``UNCHANGED`` with ``previous_label`` the (H, W) int
    ``labels_t`` there (the surface is seen in place in frame t), ``ARRIVED`` when frame t's
    surface lies behind it (the surface is gone), ``REVEALED`` when frame t's lies in front
    (hidden now). The frames' (H, W, 3) world points (m), (H, W) depth (m, 0 = no reading),
    (3, 3) intrinsics (px) and (4, 4) poses (world from OpenCV camera, m); ``compared``: (H, W)
    bool, the only pixels of frame t-1 to follow (the others ``NOT_COMPARED``), or None
    (all)."""
    return compare_frames(
        frames_points[t - 1],
        frames_depth[t - 1],
        frames_depth[t],
        labels_t,
        frames_K[t],
        frames_world_from_camera[t],
        config,
        K=frames_K[t - 1],
        world_from_camera=frames_world_from_camera[t - 1],
        compared=compared,
    )


def _pixel_features(
    pixels: np.ndarray, points: np.ndarray, rgb: np.ndarray, depth_m: np.ndarray | None
) -> SegmentFeatures:
    """``segment_features`` of one set of (N,) sorted flat pixel indices of a frame with
    (H, W, 3) world points (m), (H, W, 3) uint8 colours and (H, W) depth (m, 0 = no reading;
    None = all valid). The pixels may include some without depth (labels cover depth holes):
    colour from all of them, geometry from those with a reading (all when none has one)."""
    histogram = np.bincount(
        _colour_codes(rgb.reshape(-1, 3)[pixels]), minlength=COLOUR_BINS**3
    ).astype(np.float64)
    if depth_m is None:
        readings = np.ones(pixels.size)
    else:
        readings = depth_m.reshape(-1)[pixels].astype(np.float64)
    with_depth = readings > 0
    geometry = pixels[with_depth] if with_depth.any() else pixels
    points_k = points.reshape(-1, 3)[geometry]
    area = float((readings[with_depth] ** 2).sum())
    return SegmentFeatures(
        pixels,
        points_k.mean(axis=0),
        histogram / histogram.sum(),
        float(_grouped_percentile(points_k[:, 2], np.array([len(points_k)]), 98.0)[0]),
        area if area > 0 else float(pixels.size),
    )


def _relabel_part(
    labels: np.ndarray, object_id: int, new_id: int, part: np.ndarray, with_depth: np.ndarray
) -> np.ndarray:
    """(H, W) labels with the (N,) flat pixels ``part`` of ``object_id`` given ``new_id``, and
    its pixels without depth ((H*W,) ``with_depth`` False) given the id of the nearest of its
    pixels with depth."""
    from scipy.ndimage import distance_transform_edt

    result = labels.copy()
    flat = result.reshape(-1)
    flat[part] = new_id
    holes = (flat == object_id) & ~with_depth
    if holes.any():
        seeds = ((flat == object_id) | (flat == new_id)) & with_depth
        _, (rows, cols) = distance_transform_edt(~seeds.reshape(labels.shape), return_indices=True)
        nearest = flat[rows.reshape(-1) * labels.shape[1] + cols.reshape(-1)]
        flat[holes] = nearest[holes]
    return result


#: Points per segment in ``join_moved_wholes``' registration (evenly spaced in pixel order).
_WHOLE_POINTS = 800

#: Iterations of ``rigid_registration``; after the first few, pairs farther apart than
#: ``_REGISTRATION_GATE_M`` are dropped (parts seen in only one of the two frames).
_REGISTRATION_ITERATIONS = 30
_REGISTRATION_GATE_M = 0.03


def _even_points(points: np.ndarray, count: int) -> np.ndarray:
    """At most ``count`` of (N, 3) points, evenly spaced in their order (deterministic)."""
    if len(points) <= count:
        return points
    return points[np.linspace(0, len(points) - 1, count).astype(np.int64)]


def rigid_registration(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (3, 3) and translation (3,) (m) moving (N, 3) ``source`` points onto (M, 3)
    ``target`` points (world frame, m): point-to-point ICP (closed-form SVD step) started from
    the centroid shift; from the fifth iteration on, pairs farther than 3 cm are dropped, so
    surface seen in only one of the frames does not pull the fit."""
    from scipy.spatial import cKDTree

    tree = cKDTree(target)
    rotation, translation = np.eye(3), target.mean(axis=0) - source.mean(axis=0)
    for iteration in range(_REGISTRATION_ITERATIONS):
        moved = source @ rotation.T + translation
        gate = _REGISTRATION_GATE_M if iteration > 3 else np.inf
        distance, nearest = tree.query(moved, distance_upper_bound=gate)
        kept = np.isfinite(distance)
        if kept.sum() < 10:
            break
        a, b = source[kept], target[nearest[kept]]
        a_centre, b_centre = a.mean(axis=0), b.mean(axis=0)
        u, _, vt = np.linalg.svd((a - a_centre).T @ (b - b_centre))
        flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
        rotation = vt.T @ flip @ u.T
        translation = b_centre - rotation @ a_centre
    return rotation, translation


def join_moved_wholes(
    tracked: list[np.ndarray],
    frames_points: list[np.ndarray],
    frames_depth: list[np.ndarray],
    config: TrackingConfig,
) -> list[np.ndarray]:
    """Join, in every frame, an object split in frame t-1 and seen whole, moved, in frame t.

    An object cut in two in frame t-1 (a crease, a colour edge, or an occluder between the
    pieces) gives each piece an id; when a push moves it and frame t sees it as one segment,
    that segment takes one piece's id and the other piece's id is not seen again, while every
    earlier frame keeps the two ids (``merge_split_objects`` joins such pieces only when they
    touch and look alike). The rigid motion is the evidence: for an object ``a`` seen in frames
    t-1 and t that moved (less than ``whole_static_share`` of its frame t-1 points in place,
    within ``whole_inlier_m``), and an object ``b`` seen in frame t-1 but not in frame t whose
    nearest point lies within ``whole_max_gap_m`` of ``a``'s, ``a``'s frame-t points are
    registered (``rigid_registration``) onto the union of the two frame-(t-1) segments; ``b``
    joins ``a`` when the registered points cover at least ``whole_min_cover`` of each
    segment's points, move by a median of at least ``whole_min_motion_m``, and fit the union
    at least as well as ``a``'s own registration fits ``a`` alone. Two objects that touch
    are rarely seen whole as one segment after a push that moved them, and a still object is
    no evidence (the frame may merely have merged two objects). Each ``b`` joins once; joins
    chain to the first id.

    Args:
        tracked: per frame, (H, W) int tracked labels, not modified; frames_points: (H, W, 3)
            world points (m); frames_depth: (H, W) depth (m, 0 = no reading).

    Returns:
        (H, W) int32 label images, the joined ids replaced in every frame.
    """
    from scipy.spatial import cKDTree

    result = [np.asarray(labels, dtype=np.int32) for labels in tracked]
    if len(result) < 2 or not config.moved_wholes:
        return result
    inlier = config.whole_inlier_m
    joined: dict[int, int] = {}
    for t in range(1, len(result)):
        before, now = result[t - 1].reshape(-1), result[t].reshape(-1)
        valid_before = frames_depth[t - 1].reshape(-1) > 0
        valid_now = frames_depth[t].reshape(-1) > 0
        points_before = frames_points[t - 1].reshape(-1, 3)
        points_now = frames_points[t].reshape(-1, 3)
        ids_before = {int(i) for i in np.flatnonzero(np.bincount(before))} - {0}
        ids_now = {int(i) for i in np.flatnonzero(np.bincount(now))} - {0}

        def points_of(labels, valid, points, object_id):
            return _even_points(points[(labels == object_id) & valid], _WHOLE_POINTS)

        gone = {
            b: points_of(before, valid_before, points_before, b)
            for b in sorted(ids_before - ids_now)
            if b not in joined
        }
        gone = {b: p for b, p in gone.items() if len(p) >= 30}
        if not gone:
            continue
        for a in sorted(ids_before & ids_now):
            a_before = points_of(before, valid_before, points_before, a)
            a_now = points_of(now, valid_now, points_now, a)
            if len(a_before) < 30 or len(a_now) < 30:
                continue
            a_tree = cKDTree(a_before)
            in_place = cKDTree(a_now).query(a_before)[0] <= inlier
            if in_place.mean() >= config.whole_static_share:
                continue  # a did not move: no evidence
            alone_fit = None  # how well a's own registration fits a alone: once per a
            for b, b_before in list(gone.items()):
                if a_tree.query(b_before)[0].min() > config.whole_max_gap_m:
                    continue
                union = np.vstack([a_before, b_before])
                rotation, translation = rigid_registration(a_now, union)
                moved = a_now @ rotation.T + translation
                if np.median(np.linalg.norm(moved - a_now, axis=1)) < config.whole_min_motion_m:
                    continue
                moved_tree = cKDTree(moved)
                if (moved_tree.query(a_before)[0] <= inlier).mean() < config.whole_min_cover:
                    continue
                if (moved_tree.query(b_before)[0] <= inlier).mean() < config.whole_min_cover:
                    continue
                fit = (cKDTree(union).query(moved)[0] <= inlier).mean()
                if alone_fit is None:
                    alone_rotation, alone_translation = rigid_registration(a_now, a_before)
                    alone = a_tree.query(a_now @ alone_rotation.T + alone_translation)[0]
                    alone_fit = (alone <= inlier).mean()
                if fit < alone_fit:
                    continue
                joined[b] = a
                del gone[b]
    if not joined:
        return result
    final = np.arange(max(int(labels.max()) for labels in result) + 1, dtype=np.int32)
    for absorbed in joined:
        target = joined[absorbed]
        while target in joined:
            target = joined[target]
        final[absorbed] = target
    return [final[labels] for labels in result]
