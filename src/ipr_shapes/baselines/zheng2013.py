"""Zheng et al. 2013 (the paper's first baseline, ``ipr-shapes infer --method zheng2013``): volumetric
primitives under Manhattan assumptions, with geometric and physical stability reasoning.

B. Zheng, Y. Zhao, J. C. Yu, K. Ikeuchi, S.-C. Zhu, "Beyond point clouds: scene understanding
by reasoning geometry and physics", CVPR 2013. Reimplemented on ipr's perception (its partial
objects stand for the original's segments merged into primitives):

1. Manhattan frame. Up is the support's normal (gravity); the two horizontal axes are the
   scene's dominant directions: the mode, modulo 90 degrees, of the horizontal parts of the
   observed facets' normals (weighted by area), the original's Manhattan assumption
   (``frame="object"``: each object's own facets instead, a variant beyond the original).
2. Geometric reasoning (volumetric completion). Each object becomes a box in that frame: the
   bounding box of its observed points, then grown into the space the camera could not see,
   one voxel slab (``pitch_m``) at a time: down towards the support and, for each horizontal
   face turned away from the camera, behind the object, while a slab holds at most
   ``max_free_fraction`` seen-free samples and no other object's observed voxels or completed
   box. Behind, a box grows no longer than ``extent_cap_ratio`` times its longest visible
   horizontal side (the invisible space behind an object on a table reaches far; the original
   fills it up to the next surface or wall, and so would swallow the table's shadow). Objects
   are completed bottom-up, so a box stops on the boxes below it. The written solid is the
   box's 5 mm voxels minus those the free-space map saw empty (the solid occupies no space
   seen empty), as a closed voxel-face mesh.
3. Physical reasoning. All boxes are dropped together on the support and walls in MuJoCo
   (``ipr_shapes.physics``) for ``physics.stability_s``; a box whose centre of mass falls more than
   ``stable_m`` is unstable (it released potential energy, the original's measure). As the
   original groups an unstable primitive with the primitives it is attached to, each
   unstable object is welded to its touching neighbours (boxes within ``touch_m``) into one
   rigid body and the test repeated; groups that stand are kept (recorded, their shapes
   unchanged: the perception's segmentation is the output's), the rest are reported as
   unstable.

Left out of the original: its own segmentation and primitive fitting (planes and cylinders
from convexly connected segments; here the perception's objects and boxes only), the
Swendsen-Wang cut sampling over groupings with the disconnectivity graph's energy landscape
(here one deterministic grouping step), and the "freedom" (safety) term of its scene prior.

One hypothesis per object at probability 1: the result reads like any other method's.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.carving import voxel_surface
from ipr_shapes.checks import Checks, Interval, Options, check_fields
from ipr_shapes.geometry.convex import convex_mesh
from ipr_shapes.perception.free_space import FREE, SeenSpace
from ipr_shapes.perception.types import KnownPlane, PartialObject
from ipr_shapes.physics import Body, PhysicsConfig, build_world, support_of
from ipr_shapes.products import ObjectPosterior, ShapeHypothesis

logger = logging.getLogger(__name__)

METHOD = "zheng2013"
#: Facets steeper than this (|normal . up| below it) vote for the horizontal directions.
_VERTICAL_FACET = 0.7


@dataclass(frozen=True)
class ZhengConfig:
    """Settings of the Zheng et al. 2013 baseline (module doc).

    Attributes:
        frame: ``"scene"`` (one Manhattan frame, the original) or ``"object"`` (each object's).
        pitch_m: the growth step and the voxel size of the written solids (m).
        max_free_fraction: a slab with a larger share of seen-free samples stops the growth.
        extent_cap_ratio: hidden extent along a horizontal axis is at most this times the
            longest visible horizontal side of the object.
        min_extent_m: the thinnest box side (m), for objects seen as a flat patch.
        stable_m: fall of the centre of mass (m) in the stability test that counts as unstable.
        touch_m: boxes closer than this (m) are attached (grouping of unstable objects).
        physics: the simulation of the stability test.
    """

    CHECKS: ClassVar[Checks] = {
        "frame": Options("scene", "object"),
        "pitch_m": Interval(0.001, 0.05),
        "max_free_fraction": Interval(0, 1),
        "extent_cap_ratio": Interval(0, 10),
        "min_extent_m": Interval(0, 0.1),
        "stable_m": Interval(0, None, closed="neither"),
        "touch_m": Interval(0, 0.1),
    }

    frame: Literal["scene", "object"] = "scene"
    pitch_m: float = voxels.DEFAULT_PITCH_M
    max_free_fraction: float = 0.1
    extent_cap_ratio: float = 1.0
    min_extent_m: float = 0.01
    stable_m: float = 0.01
    touch_m: float = 0.005
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True, eq=False)
class ZhengOutcome:
    """What the baseline produced.

    Attributes:
        posteriors: one per object, its box at probability 1 (written solid: box minus seen
            free space), in the order of the objects given.
        frames: object id -> (3, 3) its Manhattan frame (columns: two horizontal axes, up).
        groups: the groups of object ids welded together to stand (unstable alone).
        unstable: ids of objects that stand neither alone nor with their neighbours.
    """

    posteriors: list[ObjectPosterior]
    frames: dict[int, np.ndarray]
    groups: list[tuple[int, ...]]
    unstable: tuple[int, ...]


# --------------------------------------------------------------------------------------------
# Manhattan frame


def _base_axes(up: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose third column is ``up`` (unit), the first two horizontal."""
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    u = np.cross(helper, up)
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(up, u), up])


def manhattan_frame(objects: Sequence[PartialObject], up: np.ndarray) -> np.ndarray:
    """(3, 3) rotation, columns (e1, e2, up): e1 the dominant horizontal direction, modulo
    90 degrees, of the objects' steep facets' normals weighted by area (the horizontal
    principal axis of their points when none is steep). Why: the Manhattan assumption, the
    faces of the scene's objects aligned with two orthogonal horizontal directions."""
    base = _base_axes(np.asarray(up, float))
    vote = 0j
    for obj in objects:
        for facet in obj.facets:
            normal = np.asarray(facet.normal, float)
            if abs(normal @ base[:, 2]) >= _VERTICAL_FACET:
                continue
            s, t = normal @ base[:, 0], normal @ base[:, 1]
            weight = float(facet.area_m2) * float(np.hypot(s, t))
            vote += weight * np.exp(4j * np.arctan2(t, s))
    if abs(vote) > 0:
        angle = np.angle(vote) / 4.0
    else:
        points = np.concatenate([obj.points for obj in objects]) if objects else np.zeros((0, 3))
        if len(points) < 3:
            return base
        flat = (points - points.mean(axis=0)) @ base[:, :2]
        _, vectors = np.linalg.eigh(flat.T @ flat)
        angle = float(np.arctan2(vectors[1, -1], vectors[0, -1]))
    e1 = np.cos(angle) * base[:, 0] + np.sin(angle) * base[:, 1]
    return np.column_stack([e1, np.cross(base[:, 2], e1), base[:, 2]])


# --------------------------------------------------------------------------------------------
# Geometric reasoning: boxes grown into the unseen space


@dataclass
class _Box:
    """A box [lo, hi] (3,) in Manhattan coordinates (m): world = origin + frame @ coordinates."""

    frame: np.ndarray
    origin: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def to_world(self, coordinates: np.ndarray) -> np.ndarray:
        return self.origin + coordinates @ self.frame.T

    def corners(self) -> np.ndarray:
        """(8, 3) world corners."""
        pick = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
        return self.to_world(np.where(pick, self.hi, self.lo))

    def slab(self, axis: int, sign: int, step: float, pitch: float) -> np.ndarray:
        """(N, 3) world sample points (``pitch``/2 apart at most) of the slab of thickness
        ``step`` beyond the face ``sign`` of ``axis``."""
        lo, hi = self.lo.copy(), self.hi.copy()
        if sign > 0:
            lo[axis], hi[axis] = self.hi[axis], self.hi[axis] + step
        else:
            lo[axis], hi[axis] = self.lo[axis] - step, self.lo[axis]
        inset = pitch / 4  # not the neighbours' voxels the face's edges only touch
        axes = [
            np.linspace(
                lo[k] + inset,
                max(hi[k] - inset, lo[k] + inset),
                max(2, int(np.ceil((hi[k] - lo[k]) / (pitch / 2))) + 1),
            )
            for k in range(3)
        ]
        axes[axis] = np.array([(lo[axis] + hi[axis]) / 2])
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        return self.to_world(grid)


def _keys(points: np.ndarray, pitch: float) -> np.ndarray:
    """Sorted unique ``ipr_shapes.voxels`` keys of the voxels holding (N, 3) world points."""
    return np.unique(voxels.pack(np.floor(points / pitch).astype(np.int64)))


def _grow(
    box: _Box,
    axis: int,
    sign: int,
    limit_m: float,
    space: SeenSpace | None,
    taken: np.ndarray,
    config: ZhengConfig,
) -> None:
    """Move the face (axis, sign) outwards one ``pitch_m`` slab at a time while the slab is
    not seen free (``max_free_fraction``), holds no voxel of ``taken`` (others' observed
    voxels and boxes; sorted keys) and the box's extent stays within ``limit_m``."""
    step = config.pitch_m
    while box.hi[axis] - box.lo[axis] + step <= limit_m + 1e-9:
        points = box.slab(axis, sign, step, config.pitch_m)
        if space is not None and np.mean(space.state_at(points) == FREE) > config.max_free_fraction:
            return
        if np.isin(_keys(points, config.pitch_m), taken, assume_unique=True).any():
            return
        if sign > 0:
            box.hi[axis] += step
        else:
            box.lo[axis] -= step


def _complete(
    obj: PartialObject,
    frame: np.ndarray,
    origin: np.ndarray,
    space: SeenSpace | None,
    taken: np.ndarray,
    camera_m: np.ndarray | None,
    config: ZhengConfig,
) -> _Box:
    """The object's box (module doc, step 2)."""
    coordinates = (obj.points - origin) @ frame
    lo, hi = coordinates.min(axis=0), coordinates.max(axis=0)
    lo[2] = max(lo[2], 0.0)
    hi[2] = max(hi[2], lo[2] + config.min_extent_m)
    for axis in (0, 1):  # a patch seen face-on gets a thickness (grown below if room)
        missing = config.min_extent_m - (hi[axis] - lo[axis])
        if missing > 0:
            lo[axis] -= missing / 2
            hi[axis] += missing / 2
    box = _Box(frame, origin, lo, hi)
    # Down to the support, or onto what lies below.
    _grow(box, 2, -1, box.hi[2], space, taken, config)
    if box.lo[2] < config.pitch_m:
        box.lo[2] = 0.0
    visible = max(box.hi[0] - box.lo[0], box.hi[1] - box.lo[1])
    centre = box.to_world((box.lo + box.hi) / 2)
    for axis in (0, 1):
        limit = max(config.extent_cap_ratio * visible, box.hi[axis] - box.lo[axis])
        for sign in (1, -1):
            if camera_m is not None and sign * frame[:, axis] @ (camera_m - centre) > 0:
                continue  # a face turned towards the camera was seen where it is
            _grow(box, axis, sign, limit, space, taken, config)
    return box


def _hypothesis(object_id: int, box: _Box, pitch_m: float) -> ShapeHypothesis:
    """The box as a closed convex ShapeHypothesis (index 0) with its voxels at ``pitch_m``."""
    mesh = convex_mesh(box.corners())
    if mesh is None:  # pragma: no cover - boxes have at least min_extent_m per side
        raise ValueError(f"object {object_id}: degenerate box")
    vertices, faces, volume = mesh
    return ShapeHypothesis(
        object_id,
        0,
        vertices,
        faces,
        volume,
        np.zeros(0),
        np.zeros((0, 3)),
        voxel_keys=voxels.scanline_voxels(vertices, faces, pitch_m),
        voxel_pitch_m=pitch_m,
    )


def _solid(
    hypothesis: ShapeHypothesis, obj: PartialObject, space: SeenSpace | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Closed mesh of the box's voxels not seen free (with the object's own observed voxels);
    None when nothing is removed (write the box itself)."""
    keys = hypothesis.keys()
    if space is None or keys.size == 0:
        return None
    pitch = hypothesis.voxel_pitch_m
    keep = space.state_at(voxels.centres(keys, pitch)) != FREE
    if keep.all():
        return None
    kept = voxels.union(keys[keep], voxels.intersection(keys, _keys(obj.points, pitch)))
    return voxel_surface(kept, pitch) if kept.size else None


# --------------------------------------------------------------------------------------------
# Physical reasoning: stability, grouping


def _unstable(
    hypotheses: Sequence[ShapeHypothesis],
    planes: tuple[KnownPlane, ...],
    config: ZhengConfig,
    groups: Sequence[Sequence[int]] = (),
) -> np.ndarray:
    """(n,) bool: shapes whose centre of mass falls more than ``stable_m`` when all are dropped
    together for ``physics.stability_s`` (a fall or a topple releases potential energy, the
    original's measure; the sideways shove that resolves two boxes' overlap does not); shapes
    of one of ``groups`` are welded."""
    group_of = {k: number for number, members in enumerate(groups) for k in members}
    bodies = [
        Body(h.vertices, h.faces, rigid_group=group_of.get(k, -1)) for k, h in enumerate(hypotheses)
    ]
    world = build_world(bodies, planes, config.physics)
    world.step(config.physics.stability_s)
    return world.drops() > config.stable_m


def _touching(hypotheses: Sequence[ShapeHypothesis], k: int, touch_m: float) -> list[int]:
    """Indices of the shapes whose world bounding boxes come within ``touch_m`` of shape k's."""
    low, high = hypotheses[k].bounds
    return [
        j
        for j, other in enumerate(hypotheses)
        if j != k
        and np.all(other.bounds[0] <= high + touch_m)
        and np.all(low - touch_m <= other.bounds[1])
    ]


# --------------------------------------------------------------------------------------------
# Public API


def zheng2013(
    objects: tuple[PartialObject, ...],
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    config: ZhengConfig | None = None,
    *,
    camera_m: np.ndarray | None = None,
) -> ZhengOutcome:
    """Complete the objects of one frame as Zheng et al. 2013 do (module doc).

    Args:
        objects: the frame's partial objects (world frame, m).
        space: the frame's free-space map (None: no free-space reasoning).
        planes: the frame's support and walls; without a support, up is +z at the lowest
            observed point.
        config: settings (defaults: ``ZhengConfig()``).
        camera_m: (3,) the camera's position (world, m); None: every horizontal face may grow.

    Returns:
        The posteriors (one box per object at probability 1), frames, groups and unstable ids.
    """
    config = config or ZhengConfig()
    started = time.perf_counter()
    support = support_of(planes)
    if support is not None:
        up = np.asarray(support.normal, float)
        origin = -float(support.offset) * up
    else:
        up = np.array([0.0, 0.0, 1.0])
        lowest = min((float(o.points[:, 2].min()) for o in objects), default=0.0)
        origin = np.array([0.0, 0.0, lowest])
    scene_frame = manhattan_frame(objects, up)
    pitch = config.pitch_m
    observed = {obj.id: _keys(obj.points, pitch) for obj in objects}
    order = sorted(
        range(len(objects)), key=lambda k: float(((objects[k].points - origin) @ up).min())
    )
    boxes: dict[int, ShapeHypothesis] = {}
    frames: dict[int, np.ndarray] = {}
    seconds: dict[int, float] = {}
    for k in order:
        obj = objects[k]
        object_started = time.perf_counter()
        frame = scene_frame if config.frame == "scene" else manhattan_frame((obj,), up)
        others = [keys for i, keys in observed.items() if i != obj.id]
        others += [h.keys() for h in boxes.values()]
        taken = voxels.union(*others) if others else np.zeros(0, np.int64)
        taken = np.setdiff1d(taken, observed[obj.id], assume_unique=True)
        box = _complete(obj, frame, origin, space, taken, camera_m, config)
        boxes[obj.id] = _hypothesis(obj.id, box, pitch)
        frames[obj.id] = frame
        seconds[obj.id] = time.perf_counter() - object_started

    hypotheses = [boxes[obj.id] for obj in objects]
    ids = [obj.id for obj in objects]
    groups: list[tuple[int, ...]] = []
    unstable_ids: tuple[int, ...] = ()
    if hypotheses and support is not None:
        unstable = _unstable(hypotheses, planes, config)
        welded: list[list[int]] = []
        for k in np.flatnonzero(unstable):
            if any(k in members for members in welded):
                continue
            welded.append([int(k), *_touching(hypotheses, int(k), config.touch_m)])
        if welded:
            merged = _merge(welded)
            still = _unstable(hypotheses, planes, config, merged)
            for members in merged:
                if len(members) > 1 and not still[members].any():
                    groups.append(tuple(ids[m] for m in members))
            unstable_ids = tuple(ids[k] for k in np.flatnonzero(still & unstable))
            if unstable_ids:
                logger.info("zheng2013: objects %s stand neither alone nor grouped", unstable_ids)

    posteriors = []
    for obj, hypothesis in zip(objects, hypotheses, strict=True):
        solid = _solid(hypothesis, obj, space)
        posteriors.append(
            ObjectPosterior(
                obj.id,
                (hypothesis,),
                np.ones(1),
                0,
                hypothesis,
                METHOD,
                seconds[obj.id],
                None if solid is None else (solid,),
            )
        )
    logger.debug("zheng2013: %d objects in %.3f s", len(objects), time.perf_counter() - started)
    return ZhengOutcome(posteriors, frames, groups, unstable_ids)


def _merge(groups: list[list[int]]) -> list[list[int]]:
    """Groups sharing a member joined (connected components), each sorted."""
    merged: list[set[int]] = []
    for members in groups:
        joined = set(members)
        for other in [m for m in merged if m & joined]:
            joined |= other
            merged.remove(other)
        merged.append(joined)
    return [sorted(m) for m in merged]
