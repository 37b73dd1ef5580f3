"""Perception: from RGB-D frames to tracked partial objects, facets and free space (paper Sec. III).

``perceive_scene(scene)`` runs, per frame: known-plane and robot removal, supervoxels, the
convexity-weighted graph and spectral clustering (``segmentation``); then tracking across frames
(``tracking``), each object's points from its plane-fitted depth (``denoise``) with facets
(``facets``), and the free/occupied/unknown voxel map of each frame (``free_space``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numba.core import event as numba_event

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.denoise import objects_plane_depth
from ipr_shapes.perception.facets import object_facets
from ipr_shapes.perception.free_space import SpaceMap, VoxelGrid, observe_space
from ipr_shapes.perception.kernels import (
    distinct_per_slice,
    labelled_order,
    object_pixel_geometry,
    rows_at,
)
from ipr_shapes.perception.robot import robot_pixels
from ipr_shapes.perception.segmentation import segment_frame
from ipr_shapes.perception.tracking import (
    follow_previous_frame,
    join_moved_wholes,
    split_merged_objects,
    track_segments,
)
from ipr_shapes.perception.types import FrameSegmentation, KnownPlane, PartialObject
from ipr_shapes.progress import ProgressCallback, report
from ipr_shapes.scene import Scene

__all__ = ["Perception", "PerceptionConfig", "partial_objects", "perceive_scene", "track_scene"]


@dataclass(frozen=True, eq=False)
class Perception:
    """Everything perception found in a scene.

    Attributes:
        labels: per frame, (H, W) int32 tracked object ids (0 = background, support, walls,
            robot); the same id is the same object in every frame.
        facet_labels: per frame, (H, W) int32 facet numbers (0 = none), unique within a frame.
        objects: per frame, the partial objects O_{i,t} ordered by id.
        planes: per frame, the support and walls found.
        segmentations: per frame, the untracked segmentation with its supervoxel graph.
        free_space: per frame, the voxel map (None when not computed or no object was found).
        timing_s: seconds: ``per_frame`` (list; planes to facets, tracking shared out),
            ``free_space_per_frame`` (list), and totals per step; ``kernels``: loading the
            compiled kernels from numba's cache or compiling them (``_KernelLoading``), which
            a process does once, on the first frames it perceives, and which the per-frame
            and per-step figures leave out.
    """

    labels: list[np.ndarray]
    facet_labels: list[np.ndarray]
    objects: list[tuple[PartialObject, ...]]
    planes: list[tuple[KnownPlane, ...]]
    segmentations: list[FrameSegmentation]
    free_space: list[SpaceMap | None]
    timing_s: dict = field(default_factory=dict)

    @property
    def object_ids(self) -> list[int]:
        """Every object id seen in any frame, sorted."""
        return sorted({obj.id for frame_objects in self.objects for obj in frame_objects})


def perceive_scene(
    scene: Scene,
    config: PerceptionConfig | None = None,
    *,
    with_free_space: bool = True,
    progress: ProgressCallback | None = None,
    workers: int = 1,
) -> Perception:
    """Segment, track and decompose every frame of a scene into partial objects with facets.

    ``progress`` (``ipr_shapes.progress``) hears ``perception`` as each frame is segmented (most of
    the time) and ``free_space`` as each frame's voxel map is made, frame by frame.
    ``workers`` threads make the frames' partial objects and then their free-space maps (each
    frame's from that frame alone, so the result is the same for any number; the maps'
    large numpy operations and the compiled kernels release the GIL). Segmentation and
    tracking stay sequential: each frame starts from the previous one's.
    """
    loading = _KernelLoading()
    with numba_event.install_listener("numba:compiler_lock", loading):
        return _perceive(
            scene, config or PerceptionConfig(), with_free_space, progress, workers, loading
        )


class _KernelLoading(numba_event.Listener):
    """A numba event listener that sums the seconds (the perception's clock) spent holding
    numba's compiler lock: loading a kernel from the on-disk cache or compiling it.

    A process loads each compiled kernel once, on its first call: 0.15-0.2 s on the first frame
    of a warm cache, tens of seconds to compile with an empty one. Frame figures that held it
    would report the process's start-up as the frame's cost (the gallery's first lab frame at
    0.7 s), so ``perceive_scene`` reports it apart. The lock is re-entrant (a kernel compiling
    the kernels it calls): only the outermost hold counts.
    """

    def __init__(self) -> None:
        self.seconds = 0.0
        self._depth = 0
        self._started = 0.0

    def on_start(self, event: numba_event.Event) -> None:
        if self._depth == 0:
            self._started = time.perf_counter()
        self._depth += 1

    def on_end(self, event: numba_event.Event) -> None:
        self._depth -= 1
        if self._depth == 0:
            self.seconds += time.perf_counter() - self._started


def _perceive(
    scene: Scene,
    config: PerceptionConfig,
    with_free_space: bool,
    progress: ProgressCallback | None,
    workers: int,
    loading: _KernelLoading,
) -> Perception:
    """``perceive_scene``'s work, each step's time without ``loading``'s seconds within it
    (the frames' partial objects and free space on several threads keep theirs: their windows
    overlap)."""
    count = len(scene.frames)
    segment_seconds, segmentations, points = [], [], []
    report(progress, "perception", 0, count)
    for position, frame in enumerate(scene.frames):
        started, loaded = time.perf_counter(), loading.seconds
        points.append(frame.points_world())
        segmentations.append(
            segment_frame(
                frame,
                pushes=scene.pushes,
                pusher=scene.pusher,
                config=config,
                points_world=points[-1],
                previous=(scene.frames[position - 1], segmentations[-1]) if position else None,
            )
        )
        segment_seconds.append(time.perf_counter() - started - (loading.seconds - loaded))
        report(progress, "perception", position + 1, count)

    started, loaded = time.perf_counter(), loading.seconds
    labels = track_scene([s.labels for s in segmentations], scene, points, config)
    tracking_seconds = time.perf_counter() - started - (loading.seconds - loaded)
    threaded = workers > 1 and count > 1

    def decompose(index: int):
        started, loaded = time.perf_counter(), loading.seconds
        frame = scene.frames[index]
        made = partial_objects(frame, segmentations[index], labels[index], config)
        own = 0.0 if threaded else loading.seconds - loaded
        return made, time.perf_counter() - started - own

    facet_seconds, objects, facet_labels = [], [], []
    for (frame_objects, frame_facets), seconds in _frames_in_threads(decompose, count, workers):
        objects.append(frame_objects)
        facet_labels.append(frame_facets)
        facet_seconds.append(seconds)

    free_space: list[SpaceMap | None] = [None] * len(scene.frames)
    free_seconds = [0.0] * len(scene.frames)
    grid = workspace_grid(objects, config) if with_free_space else None
    if grid is not None:

        def observe(index: int):
            started, loaded = time.perf_counter(), loading.seconds
            frame = scene.frames[index]
            # The robot is not an obstacle to hypotheses, and space behind it is unknown.
            ignore = robot_pixels(frame, scene.pushes, scene.pusher, config)
            space = observe_space(
                frame.depth_m,
                frame.K,
                frame.world_from_camera,
                grid,
                surface_margin_m=config.free_space.surface_margin_m,
                ignore_mask=ignore,
            )
            own = 0.0 if threaded else loading.seconds - loaded
            return space, time.perf_counter() - started - own

        report(progress, "free_space", 0, count)
        maps = _frames_in_threads(observe, count, workers)
        for index, (space, seconds) in enumerate(maps):
            free_space[index], free_seconds[index] = space, seconds
            report(progress, "free_space", index + 1, count)

    tracking_share = tracking_seconds / max(len(scene.frames), 1)
    per_frame = [
        s + f + tracking_share for s, f in zip(segment_seconds, facet_seconds, strict=True)
    ]
    timing = {
        "per_frame": per_frame,
        "free_space_per_frame": free_seconds,
        "segmentation": sum(segment_seconds),
        "tracking": tracking_seconds,
        "facets": sum(facet_seconds),
        "free_space": sum(free_seconds),
        "kernels": loading.seconds,
    }
    return Perception(
        labels,
        facet_labels,
        objects,
        [s.planes for s in segmentations],
        segmentations,
        free_space,
        timing,
    )


def _frames_in_threads(work, count: int, workers: int):
    """``work(index)`` of frames 0..count-1 on up to ``workers`` threads (one: in this thread),
    yielded in frame order."""
    if workers <= 1 or count <= 1:
        yield from (work(index) for index in range(count))
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(min(workers, count), thread_name_prefix="ipr-perception") as pool:
        yield from pool.map(work, range(count))


def track_scene(
    untracked: list[np.ndarray],
    scene: Scene,
    points: list[np.ndarray],
    config: PerceptionConfig,
) -> list[np.ndarray]:
    """Tracked (H, W) int32 labels of a scene's frames from their per-frame segment labels
    (``track_segments``, then ``split_merged_objects`` and ``join_moved_wholes`` when enabled);
    ``points`` are the frames' (H, W, 3) world points (m)."""
    frames = scene.frames
    follow = partial(
        follow_previous_frame,
        frames_points=points,
        frames_depth=[f.depth_m for f in frames],
        frames_K=[f.K for f in frames],
        frames_world_from_camera=[f.world_from_camera for f in frames],
        config=config,
    )
    labels = track_segments(
        untracked,
        points,
        [f.rgb for f in frames],
        config.tracking,
        frames_depth=[f.depth_m for f in frames],
        follow=follow,
    )
    if config.tracking.split_merged_objects:
        labels = split_merged_objects(
            labels,
            points,
            [f.rgb for f in frames],
            [f.depth_m for f in frames],
            [f.K for f in frames],
            [f.world_from_camera for f in frames],
            config,
        )
    if config.tracking.moved_wholes:
        labels = join_moved_wholes(labels, points, [f.depth_m for f in frames], config.tracking)
    return labels


def partial_objects(
    frame,
    segmentation: FrameSegmentation,
    labels: np.ndarray,
    config: PerceptionConfig,
) -> tuple[tuple[PartialObject, ...], np.ndarray]:
    """Partial objects with facets for one frame's (H, W) object ``labels`` (tracked ids, or
    any labelling such as ground-truth masks: ``benchmarks.ceiling_gap``), using the frame's
    ``segmentation`` for its supervoxels' normals; also the (H, W) int32 facet label image."""
    height, width = labels.shape
    flat_labels = labels.reshape(-1)
    flat_rgb = frame.rgb.reshape(-1, 3)
    valid = frame.depth_m.reshape(-1) > 0
    supervoxels = segmentation.supervoxels
    flat_supervoxel = supervoxels.labels.reshape(-1)
    facet_image = np.zeros(height * width, dtype=np.int32)
    border = np.zeros((height, width), dtype=bool)
    border[:2, :] = border[-2:, :] = border[:, :2] = border[:, -2:] = True
    border = border.reshape(-1)
    next_facet = 1
    objects = []
    # Labels may cover depth holes inside an object; its points come from valid readings.
    # Grouped by label in one compiled counting sort (``kernels.labelled_order``).
    order, object_ids, starts = labelled_order(flat_labels, valid)
    ends = np.append(starts[1:], len(order))[: len(starts)]  # no segments: no ends
    # Per-pixel quantities of all objects in one pass each (objects are slices of ``order``):
    # real frames have a dozen small segments besides the objects, and per-object calls cost.
    # Hulls take extreme points: sensor noise would bulge every hull out (denoise.py).
    depth = objects_plane_depth(
        frame.depth_m,
        order,
        np.append(starts, len(order)),
        config.denoise.window_px if config.denoise.window_px >= 3 else 1,
    )
    supervoxel_all = flat_supervoxel[order]
    has_all = supervoxel_all >= 0
    world_all, areas_all = object_pixel_geometry(
        order,
        depth,
        width,
        frame.K,
        frame.world_from_camera,
        supervoxel_all,
        np.ascontiguousarray(supervoxels.normals, dtype=np.float64),
    )
    rgb_all = rows_at(flat_rgb, order)  # compiled gather (``kernels``): flat_rgb[order]
    border_all = border[order]
    # Each object's distinct supervoxels (sorted), all objects in one compiled pass.
    distinct, distinct_bounds = distinct_per_slice(
        supervoxel_all, starts, ends, max(supervoxels.count, 1)
    )
    for number, (object_id, start, end) in enumerate(
        zip(object_ids.tolist(), starts, ends, strict=True)
    ):
        pixels = order[start:end]
        point_supervoxel = supervoxel_all[start:end]
        has_supervoxel = has_all[start:end]
        object_supervoxels = distinct[distinct_bounds[number] : distinct_bounds[number + 1]]
        world = world_all[start:end]
        areas = areas_all[start:end]
        facets, facet_of_point = object_facets(
            object_supervoxels,
            supervoxels.normals,
            supervoxels.sizes,
            supervoxels.adjacency,
            np.where(
                has_supervoxel,
                point_supervoxel,
                object_supervoxels[0] if len(object_supervoxels) else 0,
            ),
            world,
            areas,
            bandwidth=config.facets.bandwidth,
        )
        assigned = facet_of_point >= 0
        facet_image[pixels[assigned]] = facet_of_point[assigned] + next_facet
        next_facet += len(facets)
        objects.append(
            PartialObject(
                object_id,
                frame.index,
                pixels,
                world,
                rgb_all[start:end],
                facets,
                facet_of_point,
                bool(border_all[start:end].any()),
            )
        )
    return tuple(objects), facet_image.reshape(height, width)


def workspace_grid(
    objects: list[tuple[PartialObject, ...]], config: PerceptionConfig
) -> VoxelGrid | None:
    """One free-space grid for all frames: the objects' bounds plus a margin (None if no object)."""
    all_points = [obj.points for frame_objects in objects for obj in frame_objects]
    if not all_points:
        return None
    stacked = np.concatenate(all_points)
    low = np.percentile(stacked, 0.5, axis=0)
    high = np.percentile(stacked, 99.5, axis=0)
    margin = config.free_space.workspace_margin_m
    minimum = np.array([low[0] - margin, low[1] - margin, low[2] - 0.05])
    maximum = np.array([high[0] + margin, high[1] + margin, high[2] + margin])
    return VoxelGrid.around(minimum, maximum, config.free_space.voxel_m)


#: With no object found, at most this share of the first frame's depth points may lie off the
#: support and walls (``check_objects_found``); more means the support choice went wrong.
UNEXPLAINED_SHARE = 0.2
#: A point within this distance (m) of a found plane lies on it.
_ON_PLANE_M = 0.02


def check_objects_found(scene: Scene, perception: Perception) -> None:
    """Refuse a first frame in which no object was found although much of it lies off the
    support and walls (more than ``UNEXPLAINED_SHARE`` of its depth points): the support choice
    (gravity) went wrong, and an empty result would hide it. An empty table passes.

    Raises:
        SceneError: naming the frame and the fixes (--up, or camera poses).
    """
    from ipr_shapes.errors import SceneError
    from ipr_shapes.scene import GRAVITY_FIX

    if perception.objects[0]:
        return
    frame = scene.frames[0]
    points = frame.points_world()[frame.depth_m > 0]
    if len(points) == 0:
        return
    on_plane = np.zeros(len(points), dtype=bool)
    for plane in perception.planes[0]:
        on_plane |= np.abs(plane.signed_distance(points)) < _ON_PLANE_M
    share = 1.0 - float(on_plane.mean())
    if share > UNEXPLAINED_SHARE:
        raise SceneError(
            scene.path,
            f"frame {frame.index}: no object found although {100 * share:.0f} % of its depth "
            "points lie off the support and walls found: the support (gravity) was likely "
            "chosen wrongly",
            GRAVITY_FIX
            if scene.world_frame_source != "camera_poses"
            else "check the camera poses (cam_R_w2c, cam_t_w2c: world z must point up)",
        )
