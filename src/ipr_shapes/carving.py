"""Output shapes carved by the space the camera saw empty (beyond the paper).

The hypotheses are convex: the physics needs convex bodies, and a hypothesis is the hull of
the observed points with mirrored facets (paper Sec. IV-C). Most household objects are not
convex (a bowl's or a mug's inside, a drill's grip, a banana's bend), and a hull also fills
the space in front of the observed surface wherever the surface is curved or noisy. The camera
saw that space empty: a ray went through it and ended on a surface behind. So once inference
has weighed the convex candidates, each written shape is voxelised on the metric's 5 mm
lattice (centres at (n + 1/2) * pitch) and every voxel whose centre lies in front of the
observed surface along its pixel's ray is removed; the rest is written as a closed mesh of
voxel faces (``voxel_surface``). Nothing behind an observed surface or outside the image is
removed: the hidden parts stay as inferred.

The observed surface is the best estimate the perception has: each object pixel's denoised
depth (``perception.denoise``, the points the hypotheses were built from), the raw reading
elsewhere. Sensors drop readings at depth discontinuities, so a pixel without a reading takes
the nearest surface around it (the minimum over ``hole_fill_window_px``, as the free-space
map assumes); pixels with no reading around them, or on the robot, carve nothing. In frame 0 a voxel is
removed when its centre is in front of that surface at all (``first_frame_margin_m`` 0); in a
later frame, where the object moved and its registration (``ipr_shapes.fusion``) is a few millimetres
off, when it is more than ``later_frame_margin_m`` in front. Later frames are used by the
methods that use the pushes (their fused views carry the motions), frame 0 by every method.

With ``CarvingConfig.before_choice`` the candidates are carved before inference chooses among
them (``carve_hypotheses``, called by ``prepare_hypotheses``): each hypothesis keeps its convex
mesh for the physics and the constraints, and its voxels (what the medoid's IoU and the
written shape read) lose the voxels frame 0 saw empty. The medoid is the Bayes choice under
IoU loss of the shapes that will be written, and the choice of a convex hull whose bulge the
camera saw empty and of one whose hidden part differs are no longer the same question.

Why the denoised surface and not the free-space map: that map is conservative by design (a
voxel is free only when its whole footprint saw past it), whereas carving needs the best
estimate of where the surface is, and against the denoised surface no noise margin is needed.
Carving raised every method's object IoU on development scenes; the later frames' margin is
about the registration error, not tuned (docs/DESIGN_NOTES.md, "Carving by what the camera saw
empty").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from scipy.ndimage import minimum_filter

from ipr_shapes import voxels
from ipr_shapes.camera import invert_transform
from ipr_shapes.checks import Checks, Interval, Options, Predicate, check_fields
from ipr_shapes.perception.types import PartialObject
from ipr_shapes.products import ObjectPosterior, ShapeHypothesis
from ipr_shapes.scene import Frame


@dataclass(frozen=True)
class CarvingConfig:
    """How output shapes are carved (module doc).

    Attributes:
        enabled: carve the written shapes (False: write the convex hypotheses as inferred).
        first_frame_margin_m: a voxel is removed when its centre is more than this in front of
            frame 0's observed surface (m).
        later_frame_margin_m: the same for later frames, seen through the object's registered
            motion (m); it absorbs the registration error.
        later_frames: also carve with the later frames (methods that use the pushes only).
        hole_fill_window_px: a pixel without a reading takes the minimum depth over this
            window (odd; 1: holes carve nothing): sensors drop readings at depth
            discontinuities, so a missing pixel in front of a bulging hull would carve nothing;
            3 scored a little above 1 and 7 on development scenes (docs/DESIGN_NOTES.md,
            "Carving by what the camera saw empty").
        before_choice: also carve every candidate by frame 0 before inference chooses among
            them (``carve_hypotheses``; module doc), so that the medoid compares the shapes that
            are written rather than their convex hulls.
    """

    CHECKS: ClassVar[Checks] = {
        "enabled": Options(True, False),
        "first_frame_margin_m": Interval(0, None),
        "later_frame_margin_m": Interval(0, None),
        "later_frames": Options(True, False),
        "before_choice": Options(True, False),
        "hole_fill_window_px": Predicate(
            lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1 and v % 2 == 1,
            "a positive odd number of pixels",
        ),
    }

    enabled: bool = True
    first_frame_margin_m: float = 0.0
    later_frame_margin_m: float = 0.005
    later_frames: bool = True
    hole_fill_window_px: int = 3
    before_choice: bool = False

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True, eq=False)
class SurfaceView:
    """One frame's observed surface, as carving reads it.

    Attributes:
        depth_m: (H, W) planar depth of the observed surface (m), 0 where nothing is known.
        K: (3, 3) intrinsics (px).
        world_from_camera: (4, 4) OpenCV camera pose (world from camera, m).
        margin_m: how far in front of the surface a voxel centre must lie to be removed (m).
        frame_from_frame0: per object id, the (4, 4) rigid motion taking the object's frame-0
            pose to its pose in this frame (world, m); None: every object is where it was in
            frame 0 (frame 0 itself). A later frame carves only the objects it lists.
    """

    depth_m: np.ndarray
    K: np.ndarray
    world_from_camera: np.ndarray
    margin_m: float
    frame_from_frame0: Mapping[int, np.ndarray] | None = None


def observed_surface_depth(
    frame: Frame, objects: Sequence[PartialObject], hole_fill_window_px: int = 1
) -> np.ndarray:
    """(H, W) float64 depth (m) of a frame's observed surface: its raw reading, with each
    object pixel's denoised point (``PartialObject.points``, world) in its place; a pixel
    without a reading takes the minimum over the ``hole_fill_window_px`` window around it (1:
    none); 0 where nothing is known or the robot mask covers the pixel.

    Args:
        frame: an ``ipr_shapes.scene.Frame``; objects: that frame's ``PartialObject``s (points of pixel
            -1, fused from other frames, are ignored).
    """
    depth = np.asarray(frame.depth_m, dtype=np.float64).copy()
    flat = depth.reshape(-1)
    camera_from_world = invert_transform(np.asarray(frame.world_from_camera, float))
    for obj in objects:
        pixels = np.asarray(obj.pixels)
        own = pixels >= 0
        if not own.any():
            continue
        points = np.asarray(obj.points, float)[own]
        z = points @ camera_from_world[2, :3] + camera_from_world[2, 3]
        flat[pixels[own]] = np.where(flat[pixels[own]] > 0, z, 0.0)
    if hole_fill_window_px > 1:
        readings = np.where(depth > 0, depth, np.inf)
        nearest = minimum_filter(readings, size=hole_fill_window_px, mode="nearest")
        depth = np.where(depth > 0, depth, np.where(np.isfinite(nearest), nearest, 0.0))
    if getattr(frame, "robot_mask", None) is not None:
        depth[np.asarray(frame.robot_mask, bool)] = 0.0
    return depth


def seen_empty(centres: np.ndarray, view: SurfaceView) -> np.ndarray:
    """(N,) bool: which world points (N, 3) (m) ``view`` saw to be empty, i.e. lie more than
    its margin in front of the observed surface at the pixel they project to."""
    height, width = view.depth_m.shape
    camera_from_world = invert_transform(np.asarray(view.world_from_camera, float))
    camera = centres @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    z = camera[:, 2]
    in_front = z > 1e-3
    safe = np.where(in_front, z, 1.0)
    u = np.round(view.K[0, 0] * camera[:, 0] / safe + view.K[0, 2]).astype(np.int64)
    v = np.round(view.K[1, 1] * camera[:, 1] / safe + view.K[1, 2]).astype(np.int64)
    inside = in_front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    surface = np.zeros(len(centres))
    surface[inside] = view.depth_m[v[inside], u[inside]]
    return inside & (surface > 0) & (z < surface - view.margin_m)


def carve_voxels(
    keys: np.ndarray,
    object_id: int,
    views: Sequence[SurfaceView],
    pitch_m: float = voxels.DEFAULT_PITCH_M,
) -> np.ndarray:
    """The (K,) int64 ``ipr_shapes.voxels`` keys (sorted) of a shape's voxels that no view saw empty.

    ``keys`` (N,) int64 are the shape's voxels at ``pitch_m`` (m) in its frame-0 pose (world
    frame); a view with motions sees the object moved by ``frame_from_frame0[object_id]`` (and
    skips objects it has no motion for).
    """
    if keys.size == 0:
        return keys
    centres = voxels.centres(keys, pitch_m)
    keep = np.ones(len(keys), dtype=bool)
    for view in views:
        if view.frame_from_frame0 is None:
            moved = centres
        elif object_id in view.frame_from_frame0:
            motion = np.asarray(view.frame_from_frame0[object_id], float)
            moved = centres @ motion[:3, :3].T + motion[:3, 3]
        else:
            continue
        keep &= ~seen_empty(moved, view)
    return keys[keep]


def _fill_edge_contacts(occupied: np.ndarray) -> np.ndarray:
    """The (nx, ny, nz) bool occupancy with every pair of voxels that share only an edge (the
    2x2 block across it holds them and two empty voxels) joined by filling one empty voxel of
    the block, repeated until none is left: the faces of such a pair would meet four to an
    edge, which is not a manifold surface. The grid must have an empty border layer."""
    result = occupied.copy()
    for _ in range(64):
        changed = False
        for first, second in ((0, 1), (1, 2), (0, 2)):
            low = [slice(None)] * 3
            a, b, c, d = (list(low) for _ in range(4))
            a[first], a[second] = slice(None, -1), slice(None, -1)  # (i, j)
            b[first], b[second] = slice(1, None), slice(1, None)  # (i+1, j+1)
            c[first], c[second] = slice(1, None), slice(None, -1)  # (i+1, j)
            d[first], d[second] = slice(None, -1), slice(1, None)  # (i, j+1)
            va, vb, vc, vd = (result[tuple(s)] for s in (a, b, c, d))
            diagonal = va & vb & ~vc & ~vd
            anti = vc & vd & ~va & ~vb
            if diagonal.any() or anti.any():
                # Fill (i+1, j) for a diagonal pair and (i, j) for an anti-diagonal one.
                result[tuple(c)] |= diagonal
                result[tuple(a)] |= anti
                changed = True
        if not changed:
            return result
    return result  # pragma: no cover - each pass only adds voxels inside a bounded grid


def voxel_surface(
    keys: np.ndarray, pitch_m: float = voxels.DEFAULT_PITCH_M, *, with_keys: bool = False
) -> tuple[np.ndarray, ...]:
    """Closed mesh (vertices (V, 3) m, faces (F, 3) counter-clockwise from outside) of the
    union of the voxel cubes of ``keys`` (``ipr_shapes.voxels`` keys at ``pitch_m``).

    Each cube face between an occupied and an empty voxel becomes two triangles; vertices are
    shared at the lattice corners, so the surface is closed. Voxels that touch only along an
    edge are first joined (``_fill_edge_contacts``: a voxel added, never one removed), so every
    edge has exactly two faces. A voxel centre lies inside the mesh exactly when its voxel is
    in the (joined) set, which is what the metric's voxelisation reads back. ``with_keys``:
    also that set, sorted keys (the written shape's voxels, not voxelised again).
    """
    if keys.size == 0:
        empty = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        return (*empty, keys[:0]) if with_keys else empty
    index = voxels.unpack(keys)
    low = index.min(axis=0) - 1
    shape = tuple(int(n) for n in index.max(axis=0) - low + 2)
    occupied = np.zeros(shape, dtype=bool)
    occupied[tuple((index - low).T)] = True
    occupied = _fill_edge_contacts(occupied)
    corner_shape = np.array(shape) + 1
    quads = []
    for axis in range(3):
        # (axis, a, b) right-handed, so e_a x e_b = e_axis.
        a, b = (axis + 1) % 3, (axis + 2) % 3
        step = np.zeros(3, dtype=np.int64)
        step[axis] = 1
        for sign in (1, -1):
            neighbour = np.roll(occupied, -sign, axis=axis)  # the border layer is empty
            cells = np.argwhere(occupied & ~neighbour)
            if cells.size == 0:
                continue
            base = cells + (step if sign > 0 else 0)  # the face's lattice corner (min a, b)
            da, db = np.eye(3, dtype=np.int64)[a], np.eye(3, dtype=np.int64)[b]
            corners = [base, base + da, base + da + db, base + db]
            if sign < 0:
                corners = corners[::-1]
            quads.append(np.stack(corners, axis=1))
    quad_corners = np.concatenate(quads)  # (Q, 4, 3) lattice corners
    flat = np.ravel_multi_index(tuple(quad_corners.reshape(-1, 3).T), tuple(corner_shape))
    unique, inverse = np.unique(flat, return_inverse=True)
    vertices = (np.stack(np.unravel_index(unique, tuple(corner_shape)), axis=1) + low) * pitch_m
    corner_ids = inverse.reshape(-1, 4)
    faces = np.concatenate([corner_ids[:, [0, 1, 2]], corner_ids[:, [0, 2, 3]]])
    if with_keys:
        joined = np.sort(voxels.pack(np.argwhere(occupied) + low))
        return vertices.astype(np.float64), faces.astype(np.int64), joined
    return vertices.astype(np.float64), faces.astype(np.int64)


def carve_mesh(
    mesh: tuple[np.ndarray, np.ndarray],
    object_id: int,
    views: Sequence[SurfaceView],
    pitch_m: float = voxels.DEFAULT_PITCH_M,
) -> tuple[np.ndarray, np.ndarray] | None:
    """A closed mesh (vertices, faces) of a shape's voxels that no view saw empty; None when
    nothing was removed (write the shape itself) or everything was (the views contradict
    the shape; keep it rather than write nothing)."""
    vertices, faces, _ = voxels.closed_or_hull(mesh)
    return carve_shape_voxels(
        voxels.scanline_voxels(vertices, faces, pitch_m), object_id, views, pitch_m
    )


def carve_shape_voxels(
    keys: np.ndarray,
    object_id: int,
    views: Sequence[SurfaceView],
    pitch_m: float = voxels.DEFAULT_PITCH_M,
    *,
    with_keys: bool = False,
) -> tuple[np.ndarray, ...] | None:
    """``carve_mesh`` of a shape given by its voxel keys at ``pitch_m`` (``with_keys``: and
    its voxels, as ``voxel_surface`` gives them)."""
    kept = carve_voxels(keys, object_id, views, pitch_m)
    if kept.size in (0, keys.size):
        return None
    return voxel_surface(kept, pitch_m, with_keys=with_keys)


def carve_hypotheses(
    hypotheses: Sequence[ShapeHypothesis],
    object_id: int,
    views: Sequence[SurfaceView],
    pitch_m: float = voxels.DEFAULT_PITCH_M,
) -> tuple[ShapeHypothesis, ...]:
    """The hypotheses with their voxels at ``pitch_m`` carved by ``views`` (``carve_voxels``) and
    ``carved`` set, their meshes (the convex hulls) unchanged. A hypothesis the views remove
    nothing of, or everything of (they contradict it; keep it rather than nothing), is
    returned as it is."""
    carved = []
    for hypothesis in hypotheses:
        keys = hypothesis.keys(pitch_m)
        kept = carve_voxels(keys, object_id, views, pitch_m)
        if kept.size in (0, keys.size):
            carved.append(hypothesis)
            continue
        carved.append(replace(hypothesis, voxel_keys=kept, voxel_pitch_m=pitch_m, carved=True))
    return tuple(carved)


def surface_views(
    frames: Sequence[Frame],
    objects_per_frame: Sequence[Sequence[PartialObject]],
    motions: Mapping[int, Mapping[int, np.ndarray]] | None,
    config: CarvingConfig,
) -> list[SurfaceView]:
    """The views that carve: frame 0, and with ``motions`` (``FusedViews.motions``: object id
    -> later frame -> (4, 4) frame0_from_frame) and ``config.later_frames`` each later frame
    in which some object registered, for those objects.

    Args:
        frames: the scene's ``Frame``s; objects_per_frame: each frame's ``PartialObject``s.
    """
    first = frames[0]
    views = [
        SurfaceView(
            observed_surface_depth(first, objects_per_frame[0], config.hole_fill_window_px),
            np.asarray(first.K, float),
            np.asarray(first.world_from_camera, float),
            config.first_frame_margin_m,
        )
    ]
    if not motions or not config.later_frames:
        return views
    for t in range(1, len(frames)):
        moved = {
            object_id: invert_transform(np.asarray(per_frame[t], float))
            for object_id, per_frame in motions.items()
            if t in per_frame
        }
        if moved:
            views.append(
                SurfaceView(
                    observed_surface_depth(
                        frames[t], objects_per_frame[t], config.hole_fill_window_px
                    ),
                    np.asarray(frames[t].K, float),
                    np.asarray(frames[t].world_from_camera, float),
                    config.later_frame_margin_m,
                    moved,
                )
            )
    return views


def carve_posteriors(
    posteriors: Sequence[ObjectPosterior], views: Sequence[SurfaceView]
) -> list[ObjectPosterior]:
    """``ObjectPosterior``s whose written shapes (``output_meshes``: the hypotheses with
    non-zero probability, and the best) are carved by ``views``."""
    carved = []
    for posterior in posteriors:
        meshes, kept = [], []
        for k, hypothesis in enumerate(posterior.hypotheses):
            written = posterior.probabilities[k] > 0 or k == posterior.best
            # The hypotheses' own voxels (cached at generation, the same voxelisation; carved
            # already when they were carved before the choice).
            keys = hypothesis.keys(voxels.DEFAULT_PITCH_M) if written else None
            made = (
                carve_shape_voxels(keys, posterior.object_id, views, with_keys=True)
                if written
                else None
            )
            if made is None and written and hypothesis.carved:
                # Nothing more to remove: write the voxels carved before the choice, not the hull.
                made = voxel_surface(keys, with_keys=True)
            meshes.append(None if made is None else made[:2])
            kept.append(None if made is None else made[2])
        carved.append(replace(posterior, output_meshes=tuple(meshes), output_keys=tuple(kept)))
    return carved
