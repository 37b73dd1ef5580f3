"""Object identities across frames (paper Sec. III: partial objects O_{i,t} tracked over t).

Between two frames the robot pushes a few objects by some centimetres; everything else stays.
Each segment of frame t is matched to the objects known from earlier frames by a cost that
combines three cues, each robust where the others fail:

- image overlap (IoU of masks): near 1 for objects that did not move, whatever their colour;
- colour: a normalised RGB histogram, unchanged by rigid motion (Bhattacharyya distance);
- proximity: the distance between 3D centroids relative to how far a push can move an object.

The assignment is Hungarian (scipy) with a gate: a segment whose best cost exceeds
``max_match_cost`` starts a new object, and objects that find no segment keep their id for later
frames (they may reappear). Known objects are remembered as last seen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from ipr.perception.config import TrackingConfig

#: Histogram bins per RGB channel.
COLOUR_BINS = 6


@dataclass(frozen=True, eq=False)
class SegmentFeatures:
    """What tracking knows of a segment: flat pixel indices (N,), centroid (3,) m, colour
    histogram (COLOUR_BINS**3,) summing to 1."""

    pixels: np.ndarray
    centroid: np.ndarray
    histogram: np.ndarray


def segment_features(
    labels: np.ndarray, points: np.ndarray, rgb: np.ndarray
) -> dict[int, SegmentFeatures]:
    """Features of every segment k >= 1 in a (H, W) label image with (H, W, 3) world points and
    (H, W, 3) uint8 colours."""
    flat_labels = labels.reshape(-1)
    order = np.argsort(flat_labels, kind="stable")
    sorted_labels = flat_labels[order]
    ids, starts = np.unique(sorted_labels, return_index=True)
    ends = np.append(starts[1:], len(sorted_labels))
    flat_points = points.reshape(-1, 3)
    bins = (rgb.reshape(-1, 3).astype(np.int64) * COLOUR_BINS) // 256
    codes = (bins[:, 0] * COLOUR_BINS + bins[:, 1]) * COLOUR_BINS + bins[:, 2]
    features = {}
    for label, start, end in zip(ids, starts, ends, strict=True):
        if label <= 0:
            continue
        pixels = order[start:end]
        histogram = np.bincount(codes[pixels], minlength=COLOUR_BINS**3).astype(np.float64)
        features[int(label)] = SegmentFeatures(
            pixels, flat_points[pixels].mean(axis=0), histogram / histogram.sum()
        )
    return features


def match_cost(known: SegmentFeatures, segment: SegmentFeatures, config: TrackingConfig) -> float:
    """Cost (>= 0) of explaining ``segment`` as the object last seen as ``known``."""
    shared = np.intersect1d(known.pixels, segment.pixels, assume_unique=True).size
    overlap = shared / (known.pixels.size + segment.pixels.size - shared)
    # Bhattacharyya distance between colour histograms, in [0, 1].
    colour = np.sqrt(max(0.0, 1.0 - float(np.sqrt(known.histogram * segment.histogram).sum())))
    distance = min(
        float(np.linalg.norm(known.centroid - segment.centroid)) / config.max_motion_m, 1.0
    )
    return (
        config.overlap_weight * (1.0 - overlap)
        + config.colour_weight * colour
        + config.distance_weight * distance
    )


def track_segments(
    frames_labels: list[np.ndarray],
    frames_points: list[np.ndarray],
    frames_rgb: list[np.ndarray],
    config: TrackingConfig | None = None,
) -> list[np.ndarray]:
    """Relabel per-frame segments (H, W) int so that one object keeps one id in every frame.

    Frame 0's segments get ids 1..k in their own order; later segments take the id of the known
    object they match, or the next unused id. Returns new (H, W) int32 label images.
    """
    config = config or TrackingConfig()
    tracked: list[np.ndarray] = []
    known: dict[int, SegmentFeatures] = {}
    next_id = 1
    for labels, points, rgb in zip(frames_labels, frames_points, frames_rgb, strict=True):
        segments = segment_features(labels, points, rgb)
        segment_ids = sorted(segments)
        assignment: dict[int, int] = {}
        if known and segment_ids:
            known_ids = sorted(known)
            cost = np.array(
                [
                    [match_cost(known[o], segments[s], config) for o in known_ids]
                    for s in segment_ids
                ]
            )
            rows, cols = linear_sum_assignment(cost)
            for row, col in zip(rows, cols, strict=True):
                if cost[row, col] <= config.max_match_cost:
                    assignment[segment_ids[row]] = known_ids[col]
        relabelled = np.zeros(labels.shape, dtype=np.int32)
        for segment_id in segment_ids:
            object_id = assignment.get(segment_id)
            if object_id is None:
                object_id = next_id
                next_id += 1
            next_id = max(next_id, object_id + 1)
            relabelled.reshape(-1)[segments[segment_id].pixels] = object_id
            known[object_id] = segments[segment_id]
        tracked.append(relabelled)
    return tracked
