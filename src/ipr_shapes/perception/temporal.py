"""Temporal consistency of the segmentation between consecutive frames of a dynamic scene.

Between two frames the robot pushes a few objects; everything else stays where it was. Where a
pixel's surface did not move, the previous frame's segmentation is strong evidence for the
current one, and objects that did not move should be grouped as they were, whatever the
clustering of the new frame (its eigengap sees a pile whose shape the push changed) decides.

``compare_frames`` compares every pixel of frame t with frame t-1: its world point is projected
into the previous camera (so a moving camera is handled too) and its depth there compared with
the previous reading. A pixel is

- *unchanged* when the two agree within ``temporal.depth_tolerance_m`` (plus a term growing with
  depth squared, as sensor noise does); it carries the previous frame's segment there;
- *revealed* when the current surface lies behind the previous one (what was in front moved
  away: a surface of a static object, or the table, that a pushed object hid);
- *arrived* when it lies in front of the previous one (something moved there: a pushed object).

``supervoxel_anchors`` then decides, per previous segment, whether it stayed (at least
``temporal.static_fraction`` of the pixels it covered are unchanged: one that moved reveals what
was behind it, or covers its old place at another depth; one newly hidden behind a pushed object
is not trusted either) and anchors each supervoxel whose pixels are mostly unchanged pixels of a
segment that stayed to that segment. ``ipr_shapes.perception.segmentation.anchor_parts`` imposes the
anchors on the clustering: the anchored supervoxels of one previous segment form one segment,
and the rest is kept with them only if it is revealed (or shifted by at most
``temporal.near_m``: a nudged object) rather than arrived. Objects that moved are clustered
afresh.

``consistent_walls`` keeps the previous frame's walls (they do not move) and rejects a wall
found for the first time whose pixels arrived since the previous frame (the face of a pushed or
toppled box).

Anchoring keeps more ids of objects that did not move and fails fewer pushed objects, for a
few milliseconds per later frame (docs/DESIGN_NOTES.md, "Temporal consistency").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ipr_shapes.camera import invert_transform
from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.planes import static_geometry_mask
from ipr_shapes.perception.types import KnownPlane, Supervoxels

#: Pixel states of ``FrameChange.state``.
NOT_COMPARED, UNCHANGED, REVEALED, ARRIVED = 0, 1, 2, 3


@dataclass(frozen=True, eq=False)
class FrameChange:
    """Per-pixel change of frame t against frame t-1.

    Attributes:
        state: (H, W) int8: ``NOT_COMPARED`` (no depth in either frame, or outside the previous
            image), ``UNCHANGED``, ``REVEALED`` (current surface farther than the previous one
            along the previous camera's ray) or ``ARRIVED`` (nearer).
        previous_label: (H, W) int32 previous frame's segment label at the pixel's projection
            into the previous frame (0 = none or not compared).
        near: (H, W) bool, compared pixels whose depth changed by at most ``temporal.near_m``
            (None: not computed; counted as False).
    """

    state: np.ndarray
    previous_label: np.ndarray
    near: np.ndarray | None = None


def compare_frames(
    points_world: np.ndarray,
    depth_m: np.ndarray,
    previous_depth_m: np.ndarray,
    previous_labels: np.ndarray,
    previous_K: np.ndarray,
    previous_world_from_camera: np.ndarray,
    config: PerceptionConfig,
    *,
    K: np.ndarray | None = None,
    world_from_camera: np.ndarray | None = None,
    compared: np.ndarray | None = None,
) -> FrameChange:
    """Compare frame t with frame t-1 pixel by pixel (module doc).

    Args:
        points_world: (H, W, 3) world points of frame t (m); depth_m: (H, W) its depth (m, 0 =
            no reading).
        previous_depth_m: (H', W') depth of frame t-1 (m); previous_labels: (H', W') its segment
            labels (0 = none); previous_K: (3, 3) its intrinsics (px); previous_world_from_camera:
            (4, 4) its camera pose (world from OpenCV camera, m).
        K, world_from_camera: frame t's intrinsics and pose, if known: when both equal the
            previous frame's (a fixed camera), pixels are compared in place (no projection).
        compared: (H, W) bool, the only pixels of frame t to compare (the others are
            ``NOT_COMPARED``; each compared pixel's result is the same), or None (all).
    """
    height, width = depth_m.shape
    flat_depth = depth_m.reshape(-1)
    if compared is None:
        valid = np.flatnonzero(flat_depth > 0)
    else:
        valid = np.flatnonzero((flat_depth > 0) & compared.reshape(-1))
    fixed_camera = (
        K is not None
        and world_from_camera is not None
        and previous_depth_m.shape == depth_m.shape
        and np.array_equal(K, previous_K)
        and np.allclose(world_from_camera, previous_world_from_camera, rtol=0.0, atol=1e-9)
    )
    if fixed_camera:
        pixel = valid
        z = flat_depth[valid].astype(np.float32)
        inside = np.ones(valid.size, dtype=bool)
    elif K is None or world_from_camera is None:
        x, y, z = _in_previous_camera(
            points_world, depth_m, valid, previous_world_from_camera, K, world_from_camera
        )
        f32 = np.float32
        in_front = z > 1e-6
        inverse_z = f32(1.0) / np.where(in_front, z, f32(1.0))
        u = np.rint(x * inverse_z * f32(previous_K[0, 0]) + f32(previous_K[0, 2]))
        v = np.rint(y * inverse_z * f32(previous_K[1, 1]) + f32(previous_K[1, 2]))
        previous_height, previous_width = previous_depth_m.shape
        inside = in_front & (u >= 0) & (u < previous_width) & (v >= 0) & (v < previous_height)
        pixel = np.where(inside, v.astype(np.int64) * previous_width + u.astype(np.int64), 0)
    else:
        # From frame t's depth and pixel grid in float32, compiled (``kernels``): the same
        # operations as ``_in_previous_camera`` and the projection above, in one pass.
        f32 = np.float32
        relative = (invert_transform(previous_world_from_camera) @ world_from_camera).astype(f32)
        pixel, z, inside = kernels.project_to_previous(
            depth_m.astype(f32, copy=False),
            valid,
            (np.arange(width, dtype=f32) - f32(K[0, 2])) * f32(1.0 / K[0, 0]),
            (np.arange(height, dtype=f32) - f32(K[1, 2])) * f32(1.0 / K[1, 1]),
            relative,
            np.asarray(previous_K, dtype=f32),
            *previous_depth_m.shape,
        )
    # Compiled (``kernels``): the states in one pass. Each quantity keeps the precision
    # numpy gave it: tolerances in z's, the depth difference in the wider of the two depths'.
    dtype = np.result_type(z.dtype, previous_depth_m.dtype)
    state, previous_label, near = kernels.pixel_changes(
        height * width,
        valid,
        pixel,
        z,
        inside,
        previous_depth_m.reshape(-1),
        previous_labels.reshape(-1),
        z.dtype.type(config.temporal.depth_tolerance_m),
        z.dtype.type(config.temporal.depth_tolerance_quadratic),
        dtype.type(config.temporal.near_m),
        (UNCHANGED, REVEALED, ARRIVED, NOT_COMPARED),
    )
    return FrameChange(
        state.reshape(height, width),
        previous_label.reshape(height, width),
        near.reshape(height, width),
    )


def _in_previous_camera(
    points_world: np.ndarray,
    depth_m: np.ndarray,
    valid: np.ndarray,
    previous_world_from_camera: np.ndarray,
    K: np.ndarray | None,
    world_from_camera: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N,) x, y, z (m) in the previous camera of the ``valid`` pixels (flat indices) of frame t.

    With frame t's intrinsics and pose, from its (H, W) depth (m) and pixel grid in float32
    (cheaper than transforming the (H, W, 3) float64 world points, which are used otherwise).
    Camera poses are (4, 4) world from OpenCV camera (m); ``K`` (3, 3) intrinsics (px).
    """
    camera_from_world = invert_transform(previous_world_from_camera)
    if K is None or world_from_camera is None:
        camera = points_world.reshape(-1, 3)[valid] @ camera_from_world[:3, :3].T
        camera += camera_from_world[:3, 3]
        return camera[:, 0], camera[:, 1], camera[:, 2]
    height, width = depth_m.shape
    relative = (camera_from_world @ world_from_camera).astype(np.float32)
    f32 = np.float32
    ray_x = (np.arange(width, dtype=f32) - f32(K[0, 2])) * f32(1.0 / K[0, 0])
    ray_y = (np.arange(height, dtype=f32) - f32(K[1, 2])) * f32(1.0 / K[1, 1])
    z_now = depth_m.astype(f32, copy=False)
    x_now = ray_x[None, :] * z_now
    y_now = ray_y[:, None] * z_now
    return tuple(
        (
            relative[i, 0] * x_now + relative[i, 1] * y_now + relative[i, 2] * z_now
            + relative[i, 3]
        ).reshape(-1)[valid]
        for i in range(3)
    )  # fmt: skip


@dataclass(frozen=True, eq=False)
class SupervoxelChange:
    """What the previous frame says about each supervoxel of frame t.

    Attributes:
        anchor: (M,) int32 previous segment the supervoxel stays with (0 = free: moved, new,
            revealed or undecided).
        compatible_px: (M,) pixels that may belong to a static object seen before: revealed,
            or unchanged where the previous frame had no segment or one that stayed.
        incompatible_px: (M,) pixels that cannot: arrived (something moved there), or unchanged
            pixels of a previous segment that moved (it still covers them).
    """

    anchor: np.ndarray
    compatible_px: np.ndarray
    incompatible_px: np.ndarray


def supervoxel_anchors(
    supervoxels: Supervoxels, change: FrameChange, config: PerceptionConfig
) -> SupervoxelChange:
    """Anchor supervoxels to the previous segments that stayed (module doc).

    A previous segment L stayed when its unchanged pixels number at least
    ``segmentation.min_object_pixels`` and are at least ``temporal.static_fraction`` of its
    unchanged plus revealed pixels (pixels newly hidden behind something that arrived do not
    count either way). A supervoxel is anchored to L when L's unchanged pixels are at least
    ``temporal.anchor_fraction`` of its pixels.
    """
    count = supervoxels.count
    flat_supervoxel = supervoxels.labels.reshape(-1)
    state = change.state.reshape(-1)
    label = change.previous_label.reshape(-1).astype(np.int64)
    n_labels = int(label.max()) + 1 if label.size else 1
    anchor = np.zeros(count, dtype=np.int32)
    if count == 0:
        zero = np.zeros(0, dtype=np.int64)
        return SupervoxelChange(anchor, zero, zero.copy())
    near = change.near.reshape(-1) if change.near is not None else np.zeros(state.size, bool)
    # Compiled (``kernels``): every count in two passes over the pixels.
    compatible, incompatible, table, pixels = kernels.supervoxel_anchor_counts(
        flat_supervoxel,
        state,
        label,
        near,
        count,
        n_labels,
        (NOT_COMPARED, UNCHANGED, REVEALED, ARRIVED),
        config.segmentation.min_object_pixels,
        float(config.temporal.static_fraction),
    )
    # Unchanged pixels of segments that stayed, per (supervoxel, segment): the most voted
    # segment anchors the supervoxel when it holds enough of its pixels.
    if table.any():
        best_label = np.argmax(table, axis=1)  # ties: the lowest label
        votes = table[np.arange(count), best_label]
        enough = (votes > 0) & (votes >= config.temporal.anchor_fraction * pixels)
        anchor[enough] = best_label[enough]
    return SupervoxelChange(anchor, compatible, incompatible)


def same_plane(first: KnownPlane, second: KnownPlane, config: PerceptionConfig) -> bool:
    """True when two planes (world frame) agree within ``temporal.wall_angle_deg`` and
    ``temporal.wall_offset_m``."""
    cos_angle = float(np.dot(first.normal, second.normal))
    return (
        cos_angle >= np.cos(np.radians(config.temporal.wall_angle_deg))
        and abs(first.offset - second.offset) <= config.temporal.wall_offset_m
    )


def consistent_walls(
    previous_walls: tuple[KnownPlane, ...],
    found_walls: tuple[KnownPlane, ...],
    support: KnownPlane,
    above: np.ndarray,
    above_points: np.ndarray,
    state: np.ndarray,
    config: PerceptionConfig,
    previous_label: np.ndarray | None = None,
) -> tuple[KnownPlane, ...]:
    """The walls of frame t given those of frame t-1: walls do not move.

    A wall found again (``same_plane``) is kept as found now; a previous wall not found again
    (hidden, or missed by the search) is kept as it was; a wall found for the first time is
    kept unless more than ``temporal.wall_max_arrived`` of its compared pixels arrived since
    the previous frame (a face of a pushed or toppled box, not a wall revealed by the push: its
    pixels are revealed), or more than ``temporal.wall_max_object`` of them are unchanged
    pixels of an object segment of the previous frame (a box pushed against a container's
    wall and at rest since: the previous frame saw it as an object, not as a wall).

    Args:
        above: (N,) flat pixel indices of the points above the support; above_points: (N, 3)
            their world points (m); state: (H, W) ``FrameChange.state``; previous_label: (H,
            W) ``FrameChange.previous_label`` (None: not used).
    """
    flat_state = state.reshape(-1)
    flat_previous = None if previous_label is None else previous_label.reshape(-1)
    walls, found_again = [], set()
    for wall in found_walls:
        matches = [i for i, old in enumerate(previous_walls) if same_plane(old, wall, config)]
        if matches:
            found_again.update(matches)
            walls.append(wall)
            continue
        on_wall = above[static_geometry_mask(above_points, (support, wall), config)]
        states = flat_state[on_wall]
        compared = int(np.count_nonzero(states != NOT_COMPARED))
        arrived = int(np.count_nonzero(states == ARRIVED))
        if arrived > config.temporal.wall_max_arrived * compared:
            continue
        if flat_previous is not None:
            was_object = int(np.count_nonzero((states == UNCHANGED) & (flat_previous[on_wall] > 0)))
            if was_object > config.temporal.wall_max_object * compared:
                continue
        walls.append(wall)
    walls.extend(old for i, old in enumerate(previous_walls) if i not in found_again)
    return tuple(walls)
