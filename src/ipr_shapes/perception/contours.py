"""Segments split at an occluding contour (issue 27: one segment per object).

The supervoxel graph joins supervoxels whose voxels are 26-neighbours (7.5 mm voxels in a
world grid: surfaces up to about 2.6 cm apart), so an object standing a centimetre in front
of another (a strawberry before a box, a baseball against a wood block) can be joined to it
by a few edges that look convex: the ball's rim and the box's top meet like a box's two faces.
In the image the difference is plain: the two surfaces do not run on into each other
anywhere, every pixel pair across their shared outline is a depth step. A convex object's
visible surface has no such step (it cannot occlude itself), so a segment whose pixels fall
into two large parts that meet in the image only across steps is two objects, one in front
of the other.

Parts that share no outline in the image (an object seen on both sides of an occluder, a
marker across a box) stay together: no step is seen between them, the segment's own graph
joined them through the hidden surface.

docs/experiments/2026-11-27-touching-objects.md has the measurements.
"""

from __future__ import annotations

import numpy as np

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.containers import support_axes, within_footprint
from ipr_shapes.perception.types import KnownPlane, Supervoxels


def split_at_occluding_contours(
    segment_of_supervoxel: np.ndarray,
    supervoxels: Supervoxels,
    points: np.ndarray,
    viewpoint: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
) -> np.ndarray:
    """(M,) int32 segments with each segment cut in two where its surface is two surfaces
    meeting only across depth steps.

    ``segment_of_supervoxel`` (M,) int, 0 = none; ``supervoxels`` their pixels, sizes,
    centres and normals (world); ``points`` (H, W, 3) world (m); ``viewpoint`` (3,) the
    camera's centre (world, m); ``support`` the support plane (footprints are measured on it).

    Within a segment, supervoxels are connected when some 4-neighbour pixel pair between them
    has points closer than ``segmentation.contour_gap_m`` (the surface runs on). A segment
    whose connected parts include exactly two of at least ``segmentation.contour_split_px``
    pixels, which are image neighbours along at least ``segmentation.contour_min_pairs``
    pixel pairs (all of them steps, else they would be one part) whose two supervoxels both
    face the camera (the cosine of their normal with the ray to their centre at least
    ``segmentation.contour_facing_cos``), is split between them. A step next to a surface
    seen edge-on proves nothing: neighbouring pixels on a box's side face seen at a grazing
    angle are centimetres apart. Smaller parts go with the large part they share most pixel
    pairs with. The new segment takes the next free label (so labels are no longer by
    decreasing size); the others keep theirs. With three or more large parts the segment is
    left alone (which of them belong together is not asked here), and so is a pair of which one
    lies within the other's footprint on the support (``_one_within_other``: a container's
    inside).
    """
    seg = config.segmentation
    if seg.contour_split_px <= 0 or len(segment_of_supervoxel) == 0:
        return segment_of_supervoxel
    segment_of_supervoxel = np.asarray(segment_of_supervoxel)
    part, pairs = kernels.segment_surface_parts(
        supervoxels.labels, segment_of_supervoxel, points, float(seg.contour_gap_m)
    )
    if len(pairs) == 0:
        return segment_of_supervoxel
    count = len(segment_of_supervoxel)
    # Only segments with more than one part: a part is within one segment by construction.
    labelled = segment_of_supervoxel > 0
    n_segments = int(segment_of_supervoxel.max()) + 1
    lowest = np.full(n_segments, count, dtype=np.int64)
    highest = np.full(n_segments, -1, dtype=np.int64)
    np.minimum.at(lowest, segment_of_supervoxel[labelled], part[labelled])
    np.maximum.at(highest, segment_of_supervoxel[labelled], part[labelled])
    several = highest > lowest
    if not several.any():
        return segment_of_supervoxel
    result = segment_of_supervoxel.astype(np.int32).copy()
    part_px = np.bincount(part, weights=supervoxels.sizes, minlength=count)
    ray = viewpoint[None, :] - supervoxels.centres
    facing_cos = np.einsum("mc,mc->m", supervoxels.normals, ray) / np.maximum(
        np.linalg.norm(ray, axis=1), 1e-12
    )
    facing = facing_cos >= seg.contour_facing_cos
    seen_step = facing[pairs[:, 0]] & facing[pairs[:, 1]]
    part_a, part_b = part[pairs[:, 0]], part[pairs[:, 1]]  # every pair here is a step
    between = part_a != part_b
    next_label = int(segment_of_supervoxel.max()) + 1
    pixel_part = None
    for s in np.flatnonzero(several):
        nodes = np.flatnonzero(segment_of_supervoxel == s)
        parts = np.unique(part[nodes])
        large = parts[part_px[parts] >= seg.contour_split_px]
        if len(large) != 2:
            continue
        in_segment = between & (segment_of_supervoxel[pairs[:, 0]] == s)
        a, b = part_a[in_segment], part_b[in_segment]
        across = ((a == large[0]) & (b == large[1])) | ((a == large[1]) & (b == large[0]))
        shared = int(np.sum(across & seen_step[in_segment]))
        if shared < seg.contour_min_pairs:
            continue
        if pixel_part is None:
            pixel_part = np.where(supervoxels.labels >= 0, part[supervoxels.labels], -1).reshape(-1)
        if _one_within_other(pixel_part, large, points.reshape(-1, 3), support, config):
            continue
        # Smaller parts follow the large part they border most (in pixel pairs; ties and
        # parts bordering neither stay with the first large part, the one with the smallest
        # supervoxel).
        side = {int(large[0]): 0, int(large[1]): 1}
        for p in parts:
            if int(p) in side:
                continue
            votes = np.zeros(2)
            for k, big in enumerate(large):
                votes[k] = np.sum(((a == p) & (b == big)) | ((a == big) & (b == p)))
            side[int(p)] = int(votes[1] > votes[0])
        moved = np.array([side[int(part[n])] == 1 for n in nodes])
        result[nodes[moved]] = next_label
        next_label += 1
    return result


#: Points of a part used for its footprint (an even subset).
_MAX_POINTS = 2000


def _one_within_other(
    pixel_part: np.ndarray,
    large: np.ndarray,
    points: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
) -> bool:
    """Whether one of the two parts lies within the other's footprint on the support: at least
    ``containers.footprint_fraction`` of its points project into the circle fitted to the
    other's footprint (``containers.footprint_circle``) or its convex hull, grown by
    ``containers.margin_m`` (the containers' rule: an open container's inside, seen over its
    front wall, is within the wall's circle, and the wall occludes it as one object occludes
    another).

    ``pixel_part`` (H * W,) part of each pixel (-1 = none); ``large`` the two parts;
    ``points`` (H * W, 3) world (m)."""
    axis_u, axis_v = support_axes(support)
    footprints = []
    for p in large:
        pixels = np.flatnonzero(pixel_part == p)
        pixels = pixels[:: -(-pixels.size // _MAX_POINTS)]
        world = kernels.rows_at(points, pixels)
        footprints.append(np.stack([world @ axis_u, world @ axis_v], axis=1))
    return within_footprint(footprints[0], footprints[1], config.containers) or within_footprint(
        footprints[1], footprints[0], config.containers
    )
