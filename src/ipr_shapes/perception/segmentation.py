"""Segmentation of one RGB-D frame into objects (paper Sec. III-A).

Steps, as in the paper:

1. remove the known planes (support, container walls, drawer front; ``planes.py``) and the
   robot/pusher pixels (``robot.py``);
2. over-segment the rest into supervoxels with normals (``supervoxels.py``);
3. weight the supervoxel adjacency graph by convexity (``edge_weights``);
4. cluster it by spectral clustering: normalised Laplacian, number of objects from the
   eigengap, k-means on the row-normalised eigenvectors (``cluster_supervoxels``).

Then, beyond the paper, for real sensors: segments meeting along a smoothly curved concave
surface are joined (``curvature.py``), a segment of two parts seen only across depth
steps is split in two (``contours.py``), and so is one of two convex surfaces meeting at a
concave crease inside its 3D convex hull (``creases.py``), support residue and clutter beyond the table dropped
(``workspace.py``), open containers' insides joined to them (``containers.py``), small fragments
joined to the surface they continue (``fragments.py``) and, opt-in, packed boxes cut at colour
seams (``seams.py``).

Each connected component of the graph is clustered on its own: components are objects or piles
that touch nothing else, so clustering them separately is both faster (small eigenproblems) and
more robust (the eigengap of one pile is not mixed with another's).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.linalg import eigh
from scipy.sparse import coo_matrix, csr_matrix, identity
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import eigsh

from ipr_shapes.errors import IprError
from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.containers import join_container_insides
from ipr_shapes.perception.contours import split_at_occluding_contours
from ipr_shapes.perception.creases import split_at_creases
from ipr_shapes.perception.curvature import join_curved_segments, smooth_concave_edges
from ipr_shapes.perception.fragments import fragment_borders, join_fragments
from ipr_shapes.perception.occluder_splits import join_occluder_splits
from ipr_shapes.perception.planes import find_support_plane, find_walls, static_geometry_mask
from ipr_shapes.perception.robot import robot_pixels
from ipr_shapes.perception.seams import Normals, cut_colour_seams
from ipr_shapes.perception.supervoxels import compute_supervoxels, organised_normals_at
from ipr_shapes.perception.temporal import (
    SupervoxelChange,
    compare_frames,
    consistent_walls,
    supervoxel_anchors,
)
from ipr_shapes.perception.thin import join_thin_pieces
from ipr_shapes.perception.types import DepthView, FrameSegmentation, KnownPlane, Supervoxels
from ipr_shapes.perception.workspace import drop_beyond_support
from ipr_shapes.scene import Frame, Push, Pusher


class SegmentationError(IprError):
    """A frame cannot be segmented (no support plane in it)."""


def segment_frame(
    frame: Frame,
    *,
    pushes: Sequence[Push] = (),
    pusher: Pusher | None = None,
    config: PerceptionConfig = PerceptionConfig(),  # noqa: B008 (frozen)
    points_world: np.ndarray | None = None,
    previous: tuple[Frame, FrameSegmentation] | None = None,
) -> FrameSegmentation:
    """Segment ``frame`` into objects (``points_world``: its (H, W, 3) world points, if known).

    With ``previous`` (the frame before and its segmentation), surfaces that did not move since
    that frame keep their earlier grouping (``config.temporal.anchoring``; ``anchor_parts``) and
    the walls found there stay (``config.temporal.walls``; ``ipr_shapes.perception.temporal``).

    Returns labels (H, W) int32 with 0 for background, support, walls, robot and large depth
    holes, and positive labels for the segments (numbered by decreasing size before the
    container and fragment joins, which give a joined piece its partner's label and so leave
    gaps; a segment split at an occluding contour or a crease gives its second part the next free label); pixels without depth near a segment take its label (``fill_label_holes``). A frame
    without any depth reading gives an empty segmentation (all 0, no planes, no supervoxels).

    The support is the plane the objects rest on (``planes.find_support_plane``), chosen in the
    first frame; later frames keep it.

    Raises:
        SegmentationError: the frame has depth but no support plane (the support defines what
            "above the table" means, so the frame cannot be segmented; check the camera poses or
            make the table visible).
    """
    height, width = frame.shape
    valid = frame.depth_m > 0
    if not valid.any():
        return _empty_segmentation(frame, ())
    rng = np.random.default_rng(config.seed)
    points = frame.points_world() if points_world is None else points_world
    flat_points = points.reshape(-1, 3)
    robot = robot_pixels(frame, pushes, pusher, config, points_world=points)
    usable = np.flatnonzero((valid & ~robot).reshape(-1))
    usable_points = kernels.rows_at(flat_points, usable)
    earlier = None
    if previous is not None:
        earlier = next((p for p in previous[1].planes if p.kind == "support"), None)
    support = find_support_plane(
        usable_points,
        config,
        rng,
        grid=points,
        usable=usable,
        viewpoint=frame.world_from_camera[:3, 3],
        previous=earlier,
    )
    if support is None:
        raise SegmentationError(
            f"frame {frame.index}: no support plane found (no plane within "
            f"{config.support.max_tilt_deg:g} deg of world z holding "
            f"{config.support.min_fraction:.0%} of the {usable.size} valid points); make the "
            "table visible, or check the camera poses (world z must point up), or give the "
            "up direction (--up X Y Z, in camera coordinates) for a scene without poses"
        )
    # Everything at or below the support is static. The wall search looks at an even subset
    # of the points above it (``walls.max_points``), so only those need normals here.
    above = kernels.indices_above(
        flat_points, usable, support.normal, float(support.offset), config.support.clearance_m
    )
    above_points = kernels.rows_at(flat_points, above)
    frame_change = None
    if previous is not None and (config.temporal.anchoring or config.temporal.walls):
        previous_frame, previous_segmentation = previous
        frame_change = compare_frames(
            points,
            frame.depth_m,
            previous_frame.depth_m,
            previous_segmentation.labels,
            previous_frame.K,
            previous_frame.world_from_camera,
            config,
            K=frame.K,
            world_from_camera=frame.world_from_camera,
        )
    wall_sample = above[:: -(-len(above) // config.walls.max_points)] if len(above) else above
    wall_normals = organised_normals_at(frame.depth_m, frame.K, wall_sample, config)
    walls = find_walls(
        kernels.rows_at(flat_points, wall_sample),
        support,
        config,
        rng,
        normals=wall_normals @ frame.world_from_camera[:3, :3].T.astype(np.float32),
        viewpoint=frame.world_from_camera[:3, 3],
        edge_on=previous is None,
        view=DepthView(frame.depth_m, frame.K, frame.world_from_camera),
    )
    if frame_change is not None and config.temporal.walls and previous[1].planes:
        walls = consistent_walls(
            tuple(plane for plane in previous[1].planes if plane.kind == "wall"),
            walls,
            support,
            above,
            above_points,
            frame_change.state,
            config,
            frame_change.previous_label,
        )
    planes = (support, *walls)
    keep = np.zeros(height * width, dtype=bool)
    keep[above[~static_geometry_mask(above_points, planes, config)]] = True
    supervoxels = compute_supervoxels(
        frame, keep.reshape(height, width), config, points_world=points
    )
    change = None
    if frame_change is not None and config.temporal.anchoring:
        change = supervoxel_anchors(supervoxels, frame_change, config)
    segment_of_supervoxel = cluster_supervoxels(supervoxels, config, change)
    if config.segmentation.curved_segment_vote > 0:
        segment_of_supervoxel = join_curved_segments(segment_of_supervoxel, supervoxels, config)
    if config.segmentation.contour_split_px > 0:
        segment_of_supervoxel = split_at_occluding_contours(
            segment_of_supervoxel,
            supervoxels,
            points,
            frame.world_from_camera[:3, 3],
            support,
            config,
        )
    if config.segmentation.crease_split_depth_m > 0:
        segment_of_supervoxel = split_at_creases(
            segment_of_supervoxel, supervoxels, points, support, config
        )
    lookup = np.append(segment_of_supervoxel, 0).astype(np.int32)  # label -1 -> last -> 0
    labels = fill_label_holes(
        lookup[supervoxels.labels], valid | robot, config.segmentation.label_fill_px
    )
    labels, segment_of_supervoxel = drop_support_residue(
        labels, segment_of_supervoxel, flat_points, valid.reshape(-1), support, config
    )
    if config.segmentation.workspace_share > 0:
        on_support, share = _on_support(points, valid & ~robot, support, config)
        labels, segment_of_supervoxel = drop_beyond_support(
            labels,
            segment_of_supervoxel,
            flat_points,
            valid.reshape(-1),
            support,
            on_support,
            share,
            config,
        )
    labels, segment_of_supervoxel = join_container_insides(
        labels,
        segment_of_supervoxel,
        flat_points,
        valid.reshape(-1),
        frame.depth_m,
        frame.rgb,
        support,
        config,
        viewpoint=frame.world_from_camera[:3, 3],
        view=DepthView(frame.depth_m, frame.K, frame.world_from_camera),
    )
    # The fragments' border pass serves the thin-cylinder join too when no fragment joins
    # (the same labels): one pass over the image instead of two.
    borders = None
    if config.segmentation.fragment_area_m2 > 0 and labels.max() >= 2:
        borders = fragment_borders(
            labels, points, frame.depth_m, frame.K, frame.rgb, supervoxels, config
        )
    before_fragments = labels
    labels, segment_of_supervoxel = join_fragments(
        labels,
        segment_of_supervoxel,
        points,
        frame.depth_m,
        frame.K,
        frame.rgb,
        supervoxels,
        config,
        borders=borders,
        support=support,
        viewpoint=frame.world_from_camera[:3, 3],
    )
    if labels is not before_fragments:
        borders = None  # joined: its counts no longer those of the labels
    labels, segment_of_supervoxel = join_thin_pieces(
        labels,
        segment_of_supervoxel,
        points,
        frame.depth_m,
        frame.K,
        frame.rgb,
        supervoxels,
        frame.world_from_camera[:3, 3],
        config,
        borders=borders,
    )
    if config.seams.enabled:
        labels, segment_of_supervoxel = _cut_seams(
            labels, supervoxels, frame, points, config, change, segment_of_supervoxel
        )
    if config.occluder_splits.enabled:
        labels, segment_of_supervoxel, _ = join_occluder_splits(
            labels, segment_of_supervoxel, points, frame.depth_m, frame.rgb, config.occluder_splits
        )
    return FrameSegmentation(frame.index, labels, supervoxels, segment_of_supervoxel, planes)


def _cut_seams(
    labels: np.ndarray,
    supervoxels: Supervoxels,
    frame: Frame,
    points: np.ndarray,
    config: PerceptionConfig,
    change: SupervoxelChange | None = None,
    segment_of_supervoxel: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Labels cut along colour seams (``ipr_shapes.perception.seams``), renumbered 1..k by decreasing
    size, and each supervoxel's segment (the one holding most of its pixels). When no segment
    is cut, ``labels`` and the given ``segment_of_supervoxel`` ((supervoxels,) int) as they came:
    the segmentation is then the one without the seams, numbering included.

    With the previous frame's anchors (``change``, ``temporal.anchoring``) and
    ``seams.settled``, a segment that is a previous segment that stayed (``settled_segments``)
    is not searched: its grouping, seams included, was decided in the previous frame on the same
    surface, and a seam found now on an unmoved object is a printed line the previous frame did
    not take for one (or a cut the anchors already carry)."""
    # The seams read normals at labelled pixels only, and only where they look (a sample of
    # each segment, the searched segments): computed there on demand, 0 elsewhere (each
    # pixel's normal is its own neighbours', the same as ``organised_normals`` gives it).
    rotation = frame.world_from_camera[:3, :3].T.astype(np.float32)
    normals = Normals(
        lambda flat: organised_normals_at(frame.depth_m, frame.K, flat, config) @ rotation,
        (labels > 0) & (frame.depth_m > 0),
    )
    settled = None
    if change is not None and config.seams.settled:
        settled = settled_segments(labels, supervoxels, change, config)
    cut = cut_colour_seams(
        labels, frame.rgb, points, normals, frame.depth_m, frame.K, config, settled=settled
    )
    if segment_of_supervoxel is not None and int(cut.max()) == int(labels.max()):
        return labels, segment_of_supervoxel  # nothing cut: new pieces take new ids
    sizes = np.bincount(cut.ravel())
    sizes[0] = 0
    alive = np.flatnonzero(sizes)
    new_id = np.zeros(len(sizes), dtype=np.int32)
    new_id[alive[np.argsort(-sizes[alive], kind="stable")]] = np.arange(1, len(alive) + 1)
    cut = new_id[cut]
    segment_of_supervoxel = np.zeros(supervoxels.count, dtype=np.int32)
    owned = (supervoxels.labels >= 0) & (cut > 0)
    if owned.any():
        pairs = supervoxels.labels[owned].astype(np.int64) * (len(alive) + 1) + cut[owned]
        counts = np.bincount(pairs, minlength=supervoxels.count * (len(alive) + 1))
        counts = counts.reshape(supervoxels.count, len(alive) + 1)
        has = counts.sum(axis=1) > 0
        segment_of_supervoxel[has] = np.argmax(counts[has], axis=1)
    return cut, segment_of_supervoxel


def settled_segments(
    labels: np.ndarray,
    supervoxels: Supervoxels,
    change: SupervoxelChange,
    config: PerceptionConfig,
) -> np.ndarray:
    """(labels.max() + 1,) bool: the segments of ``labels`` ((H, W) int, 0 = none) of which at
    least ``temporal.static_fraction`` of the pixels lie in supervoxels anchored to one previous
    segment (``change.anchor``: a previous segment that stayed, ``temporal.supervoxel_anchors``):
    the same surface, unmoved, as one segment of the previous frame."""
    count = int(labels.max()) + 1
    settled = np.zeros(count, dtype=bool)
    flat_labels = labels.reshape(-1).astype(np.int64)
    flat_supervoxels = supervoxels.labels.reshape(-1)
    if count == 1 or len(change.anchor) == 0:
        return settled
    anchor = np.where(
        flat_supervoxels >= 0, change.anchor[np.maximum(flat_supervoxels, 0)], 0
    ).astype(np.int64)
    pixels = np.bincount(flat_labels, minlength=count)
    anchored = (flat_labels > 0) & (anchor > 0)
    if not anchored.any():
        return settled
    anchors = int(anchor.max()) + 1
    table = np.bincount(
        flat_labels[anchored] * anchors + anchor[anchored], minlength=count * anchors
    ).reshape(count, anchors)
    best = table.max(axis=1)
    settled = (best > 0) & (best >= config.temporal.static_fraction * pixels)
    settled[0] = False
    return settled


def _on_support(
    points: np.ndarray, usable: np.ndarray, support: KnownPlane, config: PerceptionConfig
) -> tuple[np.ndarray, float]:
    """The points (world, m) of every 4th row and column of the (H, W, 3) grid ``points`` where
    ``usable`` (H, W) that lie within the support's clearance, and the share of them that do
    (a grid, not every n-th pixel in row order, which leaves stripes on a far table)."""
    sample = points[::4, ::4][usable[::4, ::4]]
    if len(sample) == 0:
        return sample, 0.0
    near = np.abs(support.signed_distance(sample)) < config.support.clearance_m
    return sample[near], float(near.mean())


def drop_support_residue(
    labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    valid: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Remove segments that are slivers of the support rather than objects.

    Far from the camera, depth noise and a slightly curved or tilted real table leave patches just
    above the support clearance; they segment as flat "objects" a few millimetres high, many per
    real frame. A segment whose 90th-percentile height above the support is below
    ``segmentation.min_object_height_m`` is such a patch.

    Args:
        labels: (H, W) segment labels; segment_of_supervoxel: (M,) segment of each supervoxel.
        points: (H*W, 3) world points (m); valid: (H*W,) pixels with a depth reading.

    Returns:
        The (labels, segment_of_supervoxel) with those segments set to 0.
    """
    flat = labels.reshape(-1).copy()
    # Every 4th pixel estimates the percentile well and quarters the sort.
    labelled = np.flatnonzero((flat > 0) & valid)[::4]
    if labelled.size == 0:
        return labels, segment_of_supervoxel
    # Every segment's 90th percentile (lower value), compiled: a sort per segment.
    heights = support.signed_distance(kernels.rows_at(points, labelled))
    segments, p90 = kernels.grouped_order_statistic(flat[labelled], heights, 0.9)
    residue = segments[p90 < config.segmentation.min_object_height_m]
    if residue.size == 0:
        return labels, segment_of_supervoxel
    flat[np.isin(flat, residue)] = 0
    segment_of_supervoxel = np.where(
        np.isin(segment_of_supervoxel, residue), 0, segment_of_supervoxel
    )
    return flat.reshape(labels.shape), segment_of_supervoxel


def fill_label_holes(labels: np.ndarray, valid: np.ndarray, max_distance_px: float) -> np.ndarray:
    """Labels (H, W) int32 where each pixel that is not ``valid`` (no depth) takes the label of
    the nearest valid pixel, if that pixel is at most ``max_distance_px`` away.

    The sensor drops readings along depth discontinuities (object outlines) and in small holes;
    those pixels still show the object in the image. Nearest-neighbour filling splits a dropout
    band between the surfaces on either side of it (the background's nearest pixels carry 0),
    and larger holes stay 0. Filled pixels have no 3D point: consumers that need geometry keep
    using depth > 0.

    The nearest valid pixel is found by trying the pixel offsets within the distance in order
    of increasing length (``_offsets_by_distance``; ties go to the first in row-major order):
    for a few pixels of reach this costs a quarter of a Euclidean distance transform with
    indices (scipy), a noticeable share of a real frame's perception time.
    """
    labelled = np.flatnonzero(labels.any(axis=1)), np.flatnonzero(labels.any(axis=0))
    if max_distance_px <= 0 or valid.all() or labelled[0].size == 0:
        return labels
    # Only the segments' bounding box (plus the fill distance) can change.
    reach = int(np.ceil(max_distance_px)) + 1
    height, width = labels.shape
    top, bottom = max(labelled[0][0] - reach, 0), min(labelled[0][-1] + reach + 1, height)
    left, right = max(labelled[1][0] - reach, 0), min(labelled[1][-1] + reach + 1, width)
    box = labels[top:bottom, left:right]
    box_valid = valid[top:bottom, left:right]
    if box_valid.all() or not box_valid.any():
        return labels
    result = labels.copy()
    # Compiled (``kernels``): each pixel without depth tries the offsets until one is valid.
    kernels.fill_from_nearest(
        np.ascontiguousarray(box),
        np.ascontiguousarray(box_valid),
        _offsets_by_distance(max_distance_px),
        result[top:bottom, left:right],  # a view: writes go to result
    )
    return result


def _offsets_by_distance(max_distance_px: float) -> np.ndarray:
    """(P, 2) int (row, column) offsets of length in (0, ``max_distance_px``], shortest first
    (ties in row-major order)."""
    r = int(np.floor(max_distance_px))
    d_row, d_col = np.mgrid[-r : r + 1, -r : r + 1]
    squared = d_row**2 + d_col**2
    keep = (squared > 0) & (squared <= max_distance_px**2)
    order = np.lexsort((d_col[keep], d_row[keep], squared[keep]))
    return np.stack([d_row[keep][order], d_col[keep][order]], axis=1)


def _empty_segmentation(frame: Frame, planes: tuple) -> FrameSegmentation:
    height, width = frame.shape
    supervoxels = Supervoxels(
        labels=np.full((height, width), -1, dtype=np.int32),
        centres=np.zeros((0, 3)),
        normals=np.zeros((0, 3)),
        colours=np.zeros((0, 3)),
        sizes=np.zeros(0, dtype=np.int64),
        adjacency=np.zeros((0, 2), dtype=np.int64),
    )
    return FrameSegmentation(
        frame.index,
        np.zeros((height, width), dtype=np.int32),
        supervoxels,
        np.zeros(0, dtype=np.int32),
        planes,
    )


# --------------------------------------------------------------------------------------------
# Convexity graph


def edge_weights(supervoxels: Supervoxels, config: PerceptionConfig) -> np.ndarray:
    """(E,) weights of the supervoxel adjacency edges: 1 if convex or flat, small otherwise.

    The paper's weight, w_ij = max{n_i . (c_i - c_j), n_j . (c_j - c_i), 0}, is positive
    exactly when the connection is convex, but it is 0 between coplanar neighbours (the inside
    of every flat face: a box would fall apart) and it grows with the distance between centres
    rather than with convexity. As the authors' code does, we use the LCCP classification of
    the connection (Stein et al. 2014) and turn its verdict into a two-level weight:

    - convex: (n_i - n_j) . d > 0 with d = (c_i - c_j) / |c_i - c_j| (the paper's w_ij > 0);
    - flat: normals within ``segmentation.concavity_tolerance_deg`` (LCCP: 10 degrees; noise
      makes flat neighbours look slightly concave half of the time);
    - sanity check (LCCP): a convex connection whose d runs along the crease, i.e. the angle
      between d and n_i x n_j is below ``segmentation.sanity_angle_deg`` / (1 + exp(-0.25
      (alpha - 25))), alpha the angle between the normals in degrees, is a singular
      configuration (a step seen edge-on), not a convex edge; with
      ``segmentation.sanity_sigmoid`` False the threshold is the fixed
      ``segmentation.sanity_angle_deg`` (the authors' |(n_i x n_j) . d| > cos 45 variant);
    - smoothness check (LCCP): neighbours whose centres are offset along their normals by more
      than |n_i x n_j| * seed size + ``segmentation.smoothness_threshold`` * voxel size form a
      step between parallel surfaces (a box on a box), not one surface.

    Strong = (flat or convex and sane) and smooth: weight 1. Concave or not smooth:
    ``segmentation.concave_weight``; convex but singular: ``segmentation.singular_weight``.

    LCCP's sigmoid sanity threshold segmented better than the fixed one or none, and heavier
    singular edges merged touching objects (docs/DESIGN_NOTES.md, "Edge weights").
    """
    pairs = supervoxels.adjacency
    if len(pairs) == 0:
        return np.zeros(0)
    n_i = supervoxels.normals[pairs[:, 0]]
    n_j = supervoxels.normals[pairs[:, 1]]
    offset = supervoxels.centres[pairs[:, 0]] - supervoxels.centres[pairs[:, 1]]
    distance = np.linalg.norm(offset, axis=1)
    direction = offset / np.maximum(distance, 1e-12)[:, None]
    cos_normals = np.clip(np.einsum("ec,ec->e", n_i, n_j), -1.0, 1.0)
    normal_angle = np.degrees(np.arccos(cos_normals))
    flat = normal_angle < config.segmentation.concavity_tolerance_deg
    convex = np.einsum("ec,ec->e", n_i - n_j, direction) > 0
    crease = np.cross(n_i, n_j)
    crease_norm = np.linalg.norm(crease, axis=1)
    sanity = np.full(len(pairs), config.segmentation.sanity_angle_deg)
    if config.segmentation.sanity_sigmoid:
        sanity = sanity / (1.0 + np.exp(-0.25 * (normal_angle - 25.0)))
    along_crease = np.abs(np.einsum("ec,ec->e", crease, direction)) > np.cos(
        np.radians(sanity)
    ) * np.maximum(crease_norm, 1e-12)
    singular = convex & along_crease & ~flat
    step = np.minimum(
        np.abs(np.einsum("ec,ec->e", offset, n_i)), np.abs(np.einsum("ec,ec->e", offset, n_j))
    )
    slack = config.segmentation.smoothness_threshold * config.supervoxels.voxel_size_m
    smooth = step <= crease_norm * config.supervoxels.seed_size_m + slack
    strong = (flat | (convex & ~singular)) & smooth
    join_deg = config.segmentation.concave_join_deg
    if join_deg > 0:
        colours = supervoxels.colours
        chroma = colours / np.maximum(colours.sum(axis=1, keepdims=True), 1e-6)
        alike = (
            np.linalg.norm(chroma[pairs[:, 0]] - chroma[pairs[:, 1]], axis=1)
            <= config.segmentation.concave_join_colour
        )
        strong |= ~convex & (normal_angle < join_deg) & alike & smooth
    if config.segmentation.curved_join_edges and config.segmentation.curved_join_deg > 0:
        strong |= smooth_concave_edges(supervoxels, config) & smooth
    weights = np.where(strong, 1.0, config.segmentation.concave_weight)
    weights[singular & smooth] = config.segmentation.singular_weight
    return weights


def cluster_supervoxels(
    supervoxels: Supervoxels, config: PerceptionConfig, change: SupervoxelChange | None = None
) -> np.ndarray:
    """(M,) int32 segment of each supervoxel: 0 = none (too small), 1..k by decreasing size.

    Spectral clustering per connected component of the adjacency graph; clusters that k-means
    left in pieces are split into their connected parts; with ``change`` (the comparison with
    the previous frame) the anchors are imposed (``anchor_parts``); segments smaller than
    ``segmentation.min_object_pixels`` join the neighbouring segment they are most strongly
    connected to, or are dropped when they touch none.
    """
    count = supervoxels.count
    if count == 0:
        return np.zeros(0, dtype=np.int32)
    pairs = supervoxels.adjacency
    weights = edge_weights(supervoxels, config)
    graph = _symmetric(pairs, weights, count)
    n_components, component = connected_components(graph, directed=False)
    cluster = np.zeros(count, dtype=np.int64)
    next_id = 0
    order = np.argsort(component, kind="stable")
    bounds = np.searchsorted(component[order], np.arange(n_components + 1))
    # The graph permuted once so that each component is a diagonal block: a block is a cheap
    # slice, where fancy-indexing the graph per component cost several ms per real frame.
    grouped = graph[order][:, order] if n_components > 1 else graph
    for c in range(n_components):
        nodes = order[bounds[c] : bounds[c + 1]]
        if len(nodes) <= 2:
            cluster[nodes] = next_id
            next_id += 1
            continue
        block = slice(bounds[c], bounds[c + 1])
        local = spectral_clusters(grouped[block, block], config)
        cluster[nodes] = next_id + local
        next_id += int(local.max()) + 1
    # k-means may group pieces that do not touch: split clusters into connected parts.
    inside = cluster[pairs[:, 0]] == cluster[pairs[:, 1]] if len(pairs) else np.zeros(0, bool)
    _, parts = connected_components(
        _symmetric(pairs[inside], np.ones(int(inside.sum())), count), directed=False
    )
    if change is not None:
        parts = anchor_parts(parts, change, pairs, weights)
    return _absorb_small(parts, supervoxels, pairs, weights, config)


def anchor_parts(
    parts: np.ndarray, change: SupervoxelChange, pairs: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """(M,) int64 parts with the previous frame's static segments imposed.

    The supervoxels anchored to one previous segment (``change.anchor``) form one part,
    wherever the clustering put them: an object that did not move is grouped as before, and
    two that did not move are not merged. The free supervoxels of a part that held anchored
    ones are split into their connected pieces; a piece rejoins the anchored group it shares
    the most edge weight with in that part when at least as many of its pixels are compatible
    with a static object (revealed, or unchanged) as not (arrived, or still covered by a
    segment that moved); the pieces that join no group (a pushed object clustered with a
    static one it now touches) form one new part per former part. Parts without anchored
    supervoxels are left alone.

    Args:
        parts: (M,) int part of each supervoxel (>= 0); pairs: (E, 2) adjacency;
            weights: (E,) edge weights.
    """
    anchor = change.anchor
    anchored = anchor > 0
    if not anchored.any():
        return parts
    count = len(parts)
    first_new = int(parts.max()) + 1
    _, group = np.unique(anchor[anchored], return_inverse=True)
    n_groups = int(group.max()) + 1
    group_of = np.full(count, -1, dtype=np.int64)
    group_of[anchored] = group
    result = parts.astype(np.int64).copy()
    result[anchored] = first_new + group
    touched = np.zeros(first_new, dtype=bool)
    touched[parts[anchored]] = True
    free = ~anchored & touched[parts]
    if not free.any():
        return result
    a, b = pairs[:, 0], pairs[:, 1]
    same_part = parts[a] == parts[b]
    inside = free[a] & free[b] & same_part
    _, piece = connected_components(
        _symmetric(pairs[inside], np.ones(int(inside.sum())), count), directed=False
    )
    pieces, piece_index = np.unique(piece[free], return_inverse=True)
    local = np.full(count, -1, dtype=np.int64)
    local[free] = piece_index
    compatible = np.bincount(piece_index, weights=change.compatible_px[free], minlength=len(pieces))
    incompatible = np.bincount(
        piece_index, weights=change.incompatible_px[free], minlength=len(pieces)
    )
    # Edge weight from each free piece to each anchored group, within the same part.
    strength = np.zeros((len(pieces), n_groups))
    for x, y in ((a, b), (b, a)):
        link = same_part & free[x] & anchored[y]
        np.add.at(strength, (local[x[link]], group_of[y[link]]), weights[link])
    joins = (strength.max(axis=1) > 0) & (compatible >= incompatible)
    # Pieces that join no group stay together as their part's remainder (the clustering put
    # them together; they may touch only through the anchored object, e.g. seen on both sides).
    part_of_piece = np.zeros(len(pieces), dtype=np.int64)
    part_of_piece[piece_index] = parts[free]
    target = np.where(
        joins, first_new + np.argmax(strength, axis=1), first_new + n_groups + part_of_piece
    )
    result[free] = target[piece_index]
    return result


#: Shift of the sparse eigensolver's shift-invert mode (``spectral_clusters``), below L_sym's
#: smallest eigenvalue (0).
_EIGEN_SHIFT = -0.01


def spectral_clusters(weights: csr_matrix, config: PerceptionConfig) -> np.ndarray:
    """(m,) cluster ids 0..k-1 of the nodes of one connected weighted graph (m >= 3).

    L_sym = D^-1/2 (D - W) D^-1/2; the number of clusters k is chosen from its smallest
    eigenvalues (``choose_cluster_count``); the rows of the first k eigenvectors, normalised
    to unit length, are clustered by k-means (seeded, ``segmentation.kmeans_restarts`` restarts).
    """
    m = weights.shape[0]
    degree = np.asarray(weights.sum(axis=1)).ravel()
    scale = 1.0 / np.sqrt(np.maximum(degree, 1e-12))
    wanted = min(config.segmentation.max_objects + 1, m - 1)
    values, vectors = _smallest_eigenpairs(weights, scale, wanted, config)
    k = choose_cluster_count(values, config)
    # The eigengap is searched among the eigenvalues computed; when its largest ratio is the
    # last one, the search stopped at the truncation, not at a gap (a bin of more pieces
    # than ``max_objects``): it is repeated on twice as many eigenvalues, until the largest
    # ratio lies inside the computed spectrum (``segmentation.eigengap_extend``).
    while config.segmentation.eigengap_extend and k == wanted - 1 and wanted < m - 1:
        wanted = min(2 * wanted, m - 1)
        values, vectors = _smallest_eigenpairs(weights, scale, wanted, config)
        k = choose_cluster_count(values, config)
    if k <= 1:
        return np.zeros(m, dtype=np.int64)
    embedding = vectors[:, :k]
    embedding = embedding / np.maximum(np.linalg.norm(embedding, axis=1, keepdims=True), 1e-12)
    return kmeans_labels(embedding, k, config.segmentation.kmeans_restarts, config.seed)


def _smallest_eigenpairs(
    weights: csr_matrix, scale: np.ndarray, wanted: int, config: PerceptionConfig
) -> tuple[np.ndarray, np.ndarray]:
    """The ``wanted`` smallest eigenvalues (ascending) and their eigenvectors (m, wanted) of
    L_sym = I - D^-1/2 W D^-1/2 of the (m, m) graph ``weights``, ``scale`` = D^-1/2 (m,)."""
    m = weights.shape[0]
    if m <= config.segmentation.dense_eigen_limit:
        if weights.format == "csr" and weights.data.dtype == np.float64:
            # Compiled (``kernels``): the dense L_sym in one pass, the same arithmetic.
            laplacian = kernels.dense_normalised_laplacian(
                weights.indptr, weights.indices, weights.data, scale
            )
        else:
            normalised = (weights.toarray() * scale[:, None]) * scale[None, :]
            laplacian = np.eye(m) - normalised
        return eigh(laplacian, subset_by_index=[0, wanted - 1])
    normalised = csr_matrix(weights.multiply(scale[:, None]).multiply(scale[None, :]))
    laplacian = (identity(m, format="csr") - normalised).tocsc()
    # Shift-invert: the smallest eigenvalues of L_sym are the largest of (L_sym - shift
    # I)^-1, which ARPACK finds in a few iterations with one sparse LU; L_sym's smallest
    # eigenvalue is 0, so a small negative shift keeps the factor regular. Several times
    # faster than ARPACK on D^-1/2 W D^-1/2 (whose wanted eigenvalues crowd near 1) and
    # than the dense solver on the bins' graphs (experiment 2026-11-26-perception-speed).
    start = np.full(m, 1.0 / np.sqrt(m))
    values, vectors = eigsh(
        laplacian,
        k=wanted,
        sigma=_EIGEN_SHIFT,
        which="LM",
        v0=start,
        tol=config.segmentation.eigen_tolerance,
    )
    order = np.argsort(values)
    return values[order], vectors[:, order]


def kmeans_labels(
    points: np.ndarray, k: int, restarts: int, seed: int, max_iterations: int = 100
) -> np.ndarray:
    """(m,) int64 cluster ids 0..k-1 of (m, d) points by k-means: k-means++ seeding, Lloyd
    iterations until the labels stop changing, the best of ``restarts`` runs (least inertia).

    The spectral embeddings are small (tens to a few thousand rows, k <= 21 columns) and their
    clusters well separated, so plain numpy beats scikit-learn's KMeans, whose per-call set-up
    and OpenMP start-up cost far more per call than the clustering itself, most of it waiting
    for threads on a busy machine (docs/DESIGN_NOTES.md, "Perception speed without changing
    results").
    """
    points = np.asarray(points, dtype=np.float64)
    m = len(points)
    if k <= 1:
        return np.zeros(m, dtype=np.int64)
    if m <= k:
        return np.arange(m, dtype=np.int64)
    points = np.ascontiguousarray(points)
    rng = np.random.default_rng(seed)
    best_labels, best_inertia = np.zeros(m, dtype=np.int64), np.inf
    for _ in range(max(restarts, 1)):
        # k-means++ compiled (``kernels``; k numpy passes of small calls each): the same
        # draws, a first index and then one uniform per centre, taken up front. Where the
        # squared distances sum to 0 numpy draws an index instead: that restart is redone
        # from the same generator state by ``kmeans_plus_plus``.
        state = rng.bit_generator.state
        first = rng.integers(m)
        centres, placed = kernels.kmeans_plus_plus(points, int(first), rng.random(k - 1))
        if placed < k:
            rng.bit_generator.state = state
            centres = kmeans_plus_plus(points, k, rng)
        # Lloyd iterations compiled (``kernels``): tens of small numpy calls per iteration.
        labels, inertia = kernels.lloyd_iterations(points, centres, max_iterations)
        if inertia < best_inertia:
            best_labels, best_inertia = labels, inertia
    return best_labels


def kmeans_plus_plus(points: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """(k, d) k-means++ centres of (m, d) float64 ``points``: the first a uniformly drawn
    point, each next one drawn with probability proportional to the squared distance to the
    nearest centre so far (``kernels.kmeans_plus_plus`` is the same, compiled, where those
    distances do not all vanish)."""
    m = len(points)
    centres = np.empty((k, points.shape[1]))
    centres[0] = points[rng.integers(m)]
    closest = np.sum((points - centres[0]) ** 2, axis=1)
    for c in range(1, k):
        total = closest.sum()
        if total > 0:
            # rng.choice(m, p=closest / total), same draw, without its checks of p.
            cdf = np.cumsum(closest / total)
            cdf /= cdf[-1]
            index = int(cdf.searchsorted(rng.random(), side="right"))
        else:
            index = rng.integers(m)
        centres[c] = points[index]
        closest = np.minimum(closest, np.sum((points - centres[c]) ** 2, axis=1))
    return centres


def choose_cluster_count(eigenvalues: np.ndarray, config: PerceptionConfig) -> int:
    """Number of clusters from the ascending eigenvalues of L_sym of one connected graph.

    The paper cuts the ranked eigenvalues "at the first value that significantly differs from
    the others". With strong edges of weight 1 inside objects and
    ``segmentation.concave_weight`` between them, the first k eigenvalues of a k-object graph
    are of the order of the concave weight and the next ones of the order of the objects' own
    connectivity, orders of magnitude apart. The cut is therefore the largest ratio between
    consecutive eigenvalues, each offset by ``segmentation.eigengap_floor`` (a noise floor
    that keeps ratios of near-zero values meaningless): k = argmax_k (lambda_k + floor) /
    (lambda_{k-1} + floor). A single object wins when its lambda_1 stands out from
    lambda_0 = 0 more than any later jump.
    """
    values = np.maximum(np.asarray(eigenvalues, dtype=np.float64), 0.0)
    if len(values) < 2:
        return 1
    logs = np.log(values + config.segmentation.eigengap_floor)
    return int(np.argmax(np.diff(logs))) + 1


def _symmetric(pairs: np.ndarray, weights: np.ndarray, count: int) -> csr_matrix:
    """Symmetric sparse (count, count) matrix with ``weights`` on the (E, 2) ``pairs``."""
    if len(pairs) == 0:
        return csr_matrix((count, count))
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    return coo_matrix(
        (np.concatenate([weights, weights]), (rows, cols)), shape=(count, count)
    ).tocsr()


def _absorb_small(
    parts: np.ndarray,
    supervoxels: Supervoxels,
    pairs: np.ndarray,
    weights: np.ndarray,
    config: PerceptionConfig,
) -> np.ndarray:
    """Segments 1..k (by decreasing size) from parts (M,), small parts merged or dropped.

    Parts with fewer than ``segmentation.min_object_pixels`` pixels are merged, smallest
    first, into the adjacent part with the largest total edge weight to them (with only
    concave edges between them, the one they share the most edges with); a small part with no
    neighbour is dropped.
    """
    parts = parts.copy()
    n_parts = int(parts.max()) + 1
    size = np.bincount(parts, weights=supervoxels.sizes, minlength=n_parts)
    for part in np.argsort(size, kind="stable"):
        if size[part] == 0 or size[part] >= config.segmentation.min_object_pixels:
            continue
        a, b = parts[pairs[:, 0]], parts[pairs[:, 1]]
        touching = (a == part) ^ (b == part)
        other = np.where(a[touching] == part, b[touching], a[touching])
        usable = other >= 0
        if not usable.any():
            parts[parts == part] = -1
            size[part] = 0
            continue
        other = other[usable]
        strength = np.bincount(other, weights=weights[touching][usable], minlength=n_parts)
        target = int(np.argmax(strength))
        parts[parts == part] = target
        size[target] += size[part]
        size[part] = 0
    segments = np.zeros(len(parts), dtype=np.int32)
    alive = np.flatnonzero(size > 0)
    ranking = alive[np.argsort(-size[alive], kind="stable")]
    new_id = np.zeros(n_parts + 1, dtype=np.int32)
    new_id[ranking] = np.arange(1, len(ranking) + 1, dtype=np.int32)
    segments = new_id[parts]  # -1 (dropped) -> new_id[-1] = 0
    return segments
