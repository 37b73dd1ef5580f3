"""Views of later frames registered into frame 0: pushes show the objects' hidden sides.

The paper scores shapes by how well their simulated motion under the pushes predicts the later
depth images. The later images also *show* parts that were hidden in frame 0: a pushed object
usually turns, so later frames see its hidden sides. This stage uses that directly (what
the paper leaves to future work): each object's points in a later frame t are registered onto
its frame-0 points by a rigid transform, and the points that are new (farther than
``novel_distance_m`` from every frame-0 point) join the frame-0 object, with the later frame's
facets. Hypotheses then start from a more complete object.

Registration (frame t -> frame 0, both in the world frame, metres):

- Starts: the frame-t points turned about the support normal through their centroid by
  ``yaw_starts`` evenly spaced angles (pushed objects mostly slide and turn on the support),
  then shifted so that the centroids coincide.
- Point-to-plane ICP from each start, the correspondence gate shrinking from
  ``coarse_gate_m`` to ``fine_gate_m``; target normals by PCA of ``normal_neighbours`` points.
- Score of a result: the share of frame-t points within ``fine_gate_m`` of a frame-0 point
  (overlap), minus ``free_weight`` times the share of points that land in space the other frame
  saw to be empty: frame-t points mapped into frame 0 against frame 0's free-space map, and
  frame-0 points mapped into frame t against frame t's. A right registration puts every point
  on the object's hidden or seen surface; a wrong one (a symmetric object turned the other way,
  another object's segment under a swapped id) puts some of them where the camera saw through.
- Accepted when the best start's overlap is at least ``min_overlap`` and its free shares at
  most ``max_free_share`` each; otherwise the view is left out (logged).
- New points below the support are dropped (a few millimetres of registration tilt would put
  them there, and the constraints would then reject every shape of the object); a later facet
  joins when at least half of its points are new.

Fused objects give better shapes on development scenes, at a cost taken out of the default
inference budget (docs/DESIGN_NOTES.md, "Later views fused into the frame-0 objects").

The registered motions also carry the later frames' free space back to frame 0
(``TrackedFreeSpace``, ``tracked_free_spaces``): an object's hypotheses must stay out of the
space any frame saw empty once the object's motion to that frame is applied.

Points registered from other frames carry pixel index -1 in the fused ``PartialObject`` (they
have no pixel in frame 0). Deterministic: no random draws.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.spatial import cKDTree

from ipr_shapes.checks import Checks, Interval, Options, Pair, check_fields
from ipr_shapes.perception.free_space import FREE, UNKNOWN, SpaceMap, VoxelGrid
from ipr_shapes.perception.types import Facet, KnownPlane, PartialObject
from ipr_shapes.scene import Push, Pusher

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FusionConfig:
    """Parameters of view fusion (module docstring).

    Attributes:
        enabled: fuse later frames into frame 0 (the methods that use the pushes' evidence).
        max_points: each view is evenly subsampled to at most this many points for registering.
        yaw_starts: initial turns about the support normal (evenly spaced over 360 degrees).
        iterations: ICP iterations per start.
        coarse_gate_m / fine_gate_m: correspondence gate (m) at the first / last iteration
            (geometric interpolation between them).
        normal_neighbours: points per PCA normal of the frame-0 view.
        min_overlap: share of frame-t points within ``fine_gate_m`` of frame-0 points needed.
        max_free_share: share of registered points allowed in the other frame's seen-free space
            (each direction).
        free_weight: weight of the free shares against the overlap when choosing the start.
        novel_distance_m: a registered point farther than this from every frame-0 point is new.
        min_novel_points: a view adding fewer new points than this adds nothing.
        later_free_space: hypotheses of an object whose later views register also stay out of
            the space those frames saw empty, through its registered motion
            (``TrackedFreeSpace``).
        pusher_free_space: ... and out of the volumes the pusher occupied where the object was
            not (``pushed_through``). Off by default: no measurable gain; kept, tested, for
            pushes from behind an object, whose end capsule bounds its hidden back
            (docs/DESIGN_NOTES.md, "The pusher's volume as free space (off)").
        static_tolerance_m: an object whose observed points moved less than this (mean, m)
            between the frames before and after a push, by their registered motions, stayed
            put during that push.
        settle_margin_m: a pushed object may settle back this far (m) into where the pusher
            stopped once it is withdrawn.
    """

    CHECKS: ClassVar[Checks] = {
        "enabled": Options(True, False),
        "max_points": Interval(10, None, integer=True),
        "yaw_starts": Interval(1, None, integer=True),
        "iterations": Interval(1, None, integer=True),
        ("fine_gate_m", "coarse_gate_m"): Pair(Interval(0, None, closed="neither")),
        "normal_neighbours": Interval(3, None, integer=True),
        "min_overlap": Interval(0, 1),
        "max_free_share": Interval(0, 1),
        "free_weight": Interval(0, None),
        "novel_distance_m": Interval(0, None, closed="neither"),
        "min_novel_points": Interval(0, None, integer=True),
        "later_free_space": Options(True, False),
        "pusher_free_space": Options(True, False),
        "static_tolerance_m": Interval(0, None),
        "settle_margin_m": Interval(0, None),
    }

    enabled: bool = True
    max_points: int = 1500
    yaw_starts: int = 12
    iterations: int = 25
    coarse_gate_m: float = 0.05
    fine_gate_m: float = 0.01
    normal_neighbours: int = 12
    min_overlap: float = 0.4
    max_free_share: float = 0.03
    free_weight: float = 5.0
    novel_distance_m: float = 0.006
    min_novel_points: int = 30
    later_free_space: bool = True
    pusher_free_space: bool = False
    static_tolerance_m: float = 0.005
    settle_margin_m: float = 0.003

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class Registration:
    """A rigid transform from a later frame's view of an object onto its frame-0 view.

    Attributes:
        frame0_from_frame: (4, 4) maps world points of the object's pose in the later frame to
            its pose in frame 0.
        overlap: share of the later view's points within the fine gate of frame-0 points.
        free_share: share of registered later points in frame 0's seen-free space.
        reverse_free_share: share of frame-0 points, mapped to the later pose, in the later
            frame's seen-free space.
        rmse_m: root mean square point-to-point distance of the overlapping points (m).
    """

    frame0_from_frame: np.ndarray
    overlap: float
    free_share: float
    reverse_free_share: float
    rmse_m: float


def _even_subsample(points: np.ndarray, count: int) -> np.ndarray:
    """At most ``count`` rows of (N, 3) ``points``, evenly strided (deterministic)."""
    if len(points) <= count:
        return points
    return points[np.linspace(0, len(points) - 1, count).astype(np.int64)]


def _pca_normals(points: np.ndarray, tree: cKDTree, neighbours: int) -> np.ndarray:
    """(N, 3) unit normals of (N, 3) points: the least principal direction of each point's
    ``neighbours`` nearest points (unoriented; point-to-plane ICP needs none)."""
    k = min(neighbours, len(points))
    _, index = tree.query(points, k=k)
    local = points[index.reshape(len(points), k)]
    local = local - local.mean(axis=1, keepdims=True)
    covariance = np.einsum("nki,nkj->nij", local, local)
    _, vectors = np.linalg.eigh(covariance)
    return vectors[:, :, 0]


def _rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    x, y, z = axis
    cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * cross @ cross


def _small_rotation(omega: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of the rotation vector ``omega`` (radians)."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-12:
        return np.eye(3)
    return _rotation_about(omega / angle, angle)


class _Nearest:
    """The ICP's nearest-neighbour queries on (M, 3) frame-0 points: ``cKDTree.query(points,
    distance_upper_bound=gate)``'s answers (distance (N,) m, index (N,), inf and M where no
    point is within the gate) from a compiled kd-tree in about half its time
    (``ipr_shapes.fusion_kernels``), the points split over ``workers`` threads (the kernel
    releases the GIL; each point's answer is its own, so any split gives the same)."""

    #: Points per kd-tree leaf (12: fastest of 8, 12 and 16 on ycb-dynamic registrations).
    LEAF_SIZE = 12

    def __init__(self, points: np.ndarray, workers: int = 1) -> None:
        from ipr_shapes import fusion_kernels

        self._kernel = fusion_kernels.nearest_within
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.tree = fusion_kernels.build_tree(self.points, self.LEAF_SIZE)
        self.workers = max(1, int(workers))

    def query(self, queries: np.ndarray, gate: float) -> tuple[np.ndarray, np.ndarray]:
        queries = np.ascontiguousarray(queries, dtype=np.float64)
        distance = np.empty(len(queries))
        index = np.empty(len(queries), dtype=np.int64)
        edges = np.linspace(0, len(queries), min(self.workers, len(queries)) + 1).astype(int)

        def part(first: int, last: int) -> None:
            self._kernel(
                self.points, *self.tree, queries[first:last], float(gate),
                distance[first:last], index[first:last],
            )  # fmt: skip

        if len(edges) <= 2:
            part(0, len(queries))
            return distance, index
        failures: list[BaseException] = []

        def guarded(first: int, last: int) -> None:
            try:
                part(first, last)
            except BaseException as error:  # raised in the caller, not lost in the thread
                failures.append(error)

        threads = [
            threading.Thread(target=guarded, args=(first, last))
            for first, last in zip(edges[1:-1], edges[2:], strict=True)
        ]
        for thread in threads:
            thread.start()
        part(edges[0], edges[1])
        for thread in threads:
            thread.join()
        if failures:
            raise failures[0]
        return distance, index


def _icp_starts(
    source: np.ndarray,
    target: np.ndarray,
    target_normals: np.ndarray,
    nearest: _Nearest,
    rotations: list[np.ndarray],
    translations: list[np.ndarray],
    config: FusionConfig,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Point-to-plane ICP of (N, 3) ``source`` onto (M, 3) ``target`` from each of S initial
    (rotation (3, 3), translation (3,)) pairs; returns the S refined pairs (x -> R x + t).

    The starts run in lockstep so that each iteration asks ``nearest`` (the target's) once
    for all the starts still running (S x N points, split over its threads). Each start's
    arithmetic is the one it would do alone (a point's nearest neighbour does not depend on
    the other points of the query, and each start solves its own rows), so the results are
    the same, bit for bit, for any S and any number of threads; a start stops when fewer
    than 6 points pair or its step is below 1e-6."""
    rotations, translations = list(rotations), list(translations)
    count = len(source)
    active = list(range(len(rotations)))
    for gate in np.geomspace(config.coarse_gate_m, config.fine_gate_m, config.iterations):
        if not active:
            break
        moved = np.empty((len(active), count, 3))
        for slot, start in enumerate(active):
            moved[slot] = source @ rotations[start].T + translations[start]
        distance, index = nearest.query(moved.reshape(-1, 3), gate)
        paired = np.isfinite(distance).reshape(len(active), count)
        enough = paired.sum(axis=1) >= 6
        paired &= enough[:, None]
        # The rows of every start at once (elementwise, so each start's are what it would
        # compute alone): np.cross's products and differences, written out in its order.
        matched = index.reshape(len(active), count)[paired]
        p = moved[paired]
        q, n = target[matched], target_normals[matched]
        rows = np.empty((len(p), 6))
        rows[:, 0] = p[:, 1] * n[:, 2] - p[:, 2] * n[:, 1]
        rows[:, 1] = p[:, 2] * n[:, 0] - p[:, 0] * n[:, 2]
        rows[:, 2] = p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]
        rows[:, 3:] = n
        # Linearised: ((omega x p) + t + p - q) . n = 0  ->  [p x n, n] [omega; t] = (q - p) . n
        rhs = np.einsum("ij,ij->i", q - p, n)
        ends = np.cumsum(paired.sum(axis=1))
        running = []
        for slot, start in enumerate(active):
            if not enough[slot]:
                continue
            mine = slice(ends[slot - 1] if slot else 0, ends[slot])  # this start's rows
            solution, *_ = np.linalg.lstsq(rows[mine], rhs[mine], rcond=None)
            step = _small_rotation(solution[:3])
            rotations[start] = step @ rotations[start]
            translations[start] = step @ translations[start] + solution[3:]
            if np.linalg.norm(solution) >= 1e-6:
                running.append(start)
        active = running
    return rotations, translations


def _free_shares(points: np.ndarray, space: SpaceMap | None) -> list[float]:
    """Per set of (S, N, 3) world points, the share in voxels ``space`` saw to be empty (S
    zeros without a map or points)."""
    if space is None or points.shape[1] == 0:
        return [0.0] * len(points)
    free = (space.state_at(points.reshape(-1, 3)) == FREE).reshape(points.shape[:2])
    return [float(np.mean(row)) for row in free]


def register_view(
    view: np.ndarray,
    reference: np.ndarray,
    up: np.ndarray,
    reference_space: SpaceMap | None,
    view_space: SpaceMap | None,
    config: FusionConfig | None = None,
    workers: int = 1,
) -> Registration | None:
    """Register an object's (N, 3) world points of a later frame (``view``) onto its (M, 3)
    frame-0 points (``reference``); ``up`` (3,) is the support normal, ``reference_space`` and
    ``view_space`` the two frames' free-space maps (None: not checked). Returns the best
    accepted registration or None (module docstring). ``workers`` threads share each
    nearest-neighbour query (``_Nearest``); the result is the same for any number."""
    config = config or FusionConfig()
    source = _even_subsample(np.asarray(view, float), config.max_points)
    target = _even_subsample(np.asarray(reference, float), config.max_points)
    if len(source) < 10 or len(target) < 10:
        return None
    tree = cKDTree(target)
    normals = _pca_normals(target, tree, config.normal_neighbours)
    up = np.asarray(up, float) / np.linalg.norm(up)
    source_centre, target_centre = source.mean(axis=0), target.mean(axis=0)
    angles = np.arange(config.yaw_starts) * (2 * np.pi / config.yaw_starts)
    rotations = [_rotation_about(up, float(angle)) for angle in angles]
    translations = [target_centre - rotation @ source_centre for rotation in rotations]
    nearest = _Nearest(target, workers)
    rotations, translations = _icp_starts(
        source, target, normals, nearest, rotations, translations, config
    )
    # Every start scored at once (one tree query, one map lookup per frame): each point's
    # answer is its own, so the shares are those of scoring the starts one by one.
    moved = np.empty((len(rotations), len(source), 3))
    back = np.empty((len(rotations), len(target), 3))
    for slot, (rotation, translation) in enumerate(zip(rotations, translations, strict=True)):
        moved[slot] = source @ rotation.T + translation
        back[slot] = (target - translation) @ rotation  # frame-0 points at the later pose
    distance, _ = nearest.query(moved.reshape(-1, 3), config.fine_gate_m)
    distance = distance.reshape(len(rotations), len(source))
    free = _free_shares(moved, reference_space)
    reverse = _free_shares(back, view_space)
    best, best_score = None, -np.inf
    for slot, (rotation, translation) in enumerate(zip(rotations, translations, strict=True)):
        paired = np.isfinite(distance[slot])
        overlap = float(paired.mean())
        score = overlap - config.free_weight * (free[slot] + reverse[slot])
        if score > best_score:
            hits = distance[slot][paired]
            rmse = float(np.sqrt(np.mean(hits**2))) if paired.any() else np.inf
            transform = np.eye(4)
            transform[:3, :3], transform[:3, 3] = rotation, translation
            registration = Registration(transform, overlap, free[slot], reverse[slot], rmse)
            best, best_score = registration, score
    if best is None:
        return None
    if best.overlap < config.min_overlap or max(best.free_share, best.reverse_free_share) > (
        config.max_free_share
    ):
        logger.debug(
            "view rejected: overlap %.2f, free shares %.3f / %.3f",
            best.overlap,
            best.free_share,
            best.reverse_free_share,
        )
        return None
    return best


def _transformed(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.asarray(points, float) @ transform[:3, :3].T + transform[:3, 3]


@dataclass(frozen=True, eq=False)
class FusedViews:
    """What the later frames add to frame 0's objects.

    Attributes:
        objects: frame 0's partial objects, a fused copy where a later view added points (new
            points have pixel -1; the later view's facets are appended, transformed).
        fused_frames: per object id, the later frames whose view added points.
        motions: per object id, per later frame t whose view registered (whether or not it
            added points), the (4, 4) ``frame0_from_frame`` transform of ``Registration``: an
            object that did not move has (about) the identity.
    """

    objects: tuple[PartialObject, ...]
    fused_frames: dict[int, list[int]]
    motions: dict[int, dict[int, np.ndarray]]


def _fuse_object(
    obj: PartialObject,
    objects: list[tuple[PartialObject, ...]],
    spaces: list[SpaceMap | None],
    support: KnownPlane | None,
    up: np.ndarray,
    config: FusionConfig,
    workers: int,
) -> tuple[PartialObject, list[int], dict[int, np.ndarray]]:
    """One frame-0 object completed with its later views (``fuse_views``): the (fused) object,
    the later frames that added points, and per later frame whose view registered its
    ``frame0_from_frame`` motion. Reads nothing of the other objects' results."""
    reference = np.asarray(obj.points, float)
    added_points, added_facets, frames = [], [], []
    motions: dict[int, np.ndarray] = {}
    for t in range(1, len(objects)):
        later = next((o for o in objects[t] if o.id == obj.id), None)
        if later is None or len(later.points) < config.min_novel_points:
            continue
        registration = register_view(
            later.points, reference, up, spaces[0], spaces[t], config, workers
        )
        if registration is None:
            logger.info("object %d: frame %d's view does not register; not fused", obj.id, t)
            continue
        transform = registration.frame0_from_frame
        motions[t] = transform
        moved = _transformed(transform, later.points)
        known = cKDTree(np.concatenate([reference, *added_points]))
        distance, _ = known.query(moved)
        novel = distance > config.novel_distance_m
        if support is not None:
            # A few millimetres of registration tilt would put points under the support,
            # where no object can be (the constraints would then reject every shape).
            novel &= support.signed_distance(moved) > config.novel_distance_m
        if novel.sum() < config.min_novel_points:
            continue
        added_points.append(moved[novel])
        frames.append(t)
        for facet in later.facets:
            facet_points = _transformed(transform, facet.points)
            new_share = float(np.mean(known.query(facet_points)[0] > config.novel_distance_m))
            if new_share < 0.5:
                continue  # a side frame 0 already saw
            added_facets.append(
                Facet(
                    _transformed(transform, facet.centre[None])[0],
                    transform[:3, :3] @ np.asarray(facet.normal, float),
                    facet_points,
                    float(facet.area_m2),
                )
            )
        logger.debug(
            "object %d: frame %d fused (%d new points, overlap %.2f, rmse %.1f mm)",
            obj.id,
            t,
            int(novel.sum()),
            registration.overlap,
            registration.rmse_m * 1e3,
        )
    if not added_points:
        return obj, [], motions
    extra = np.concatenate(added_points)
    facet_of_point = obj.facet_of_point
    if facet_of_point is not None:
        facet_of_point = np.concatenate([facet_of_point, np.full(len(extra), -1)])
    fused = PartialObject(
        obj.id,
        obj.frame,
        np.concatenate([obj.pixels, np.full(len(extra), -1, dtype=obj.pixels.dtype)]),
        np.concatenate([reference, extra]),
        np.concatenate([obj.colours, np.zeros((len(extra), 3), dtype=obj.colours.dtype)]),
        tuple(obj.facets) + tuple(added_facets),
        facet_of_point,
        obj.touches_border,
    )
    return fused, frames, motions


def fuse_views(
    objects: list[tuple[PartialObject, ...]],
    spaces: list[SpaceMap | None],
    support: KnownPlane | None,
    config: FusionConfig | None = None,
    workers: int = 1,
) -> FusedViews:
    """Frame 0's partial objects completed with what later frames saw of them.

    Args:
        objects: per frame, the tracked partial objects (``Perception.objects``).
        spaces: per frame, the free-space map (``Perception.free_space``).
        support: frame 0's support plane (its normal is the turning axis), or None (world z).
        config: parameters (module docstring).
        workers: threads: with several objects, as many objects are fused at once (each
            object's registrations are its own; the compiled queries release the GIL and
            overlap the other object's numpy work); with one, its k-d tree queries are split
            (``register_view``). The result is the same for any number.

    Returns:
        The fused objects, the frames fused per object and every accepted registration
        (``FusedViews``).
    """
    config = config or FusionConfig()
    if not objects:
        return FusedViews((), {}, {})
    up = np.array([0.0, 0.0, 1.0]) if support is None else np.asarray(support.normal, float)
    first = list(objects[0])
    threads = min(max(1, int(workers)), len(first))

    def one(obj: PartialObject, query_workers: int):
        return _fuse_object(obj, objects, spaces, support, up, config, query_workers)

    if threads > 1:
        # The most points first, so that the threads finish together; results in object order.
        order = sorted(range(len(first)), key=lambda k: -len(first[k].points))
        results: list = [None] * len(first)
        with ThreadPoolExecutor(threads, thread_name_prefix="ipr-fusion") as pool:
            futures = {k: pool.submit(one, first[k], 1) for k in order}
            for k, future in futures.items():
                results[k] = future.result()
    else:
        results = [one(obj, workers) for obj in first]
    fused, used, motions = [], {}, {}
    for obj, (result, frames, moved) in zip(first, results, strict=True):
        fused.append(result)
        if moved:
            motions[int(obj.id)] = moved
        if frames:
            used[obj.id] = frames
    return FusedViews(tuple(fused), used, motions)


@dataclass(frozen=True, eq=False)
class SweptCapsule:
    """The volume a capsule pusher swept during one straight push (world frame, metres): every
    point within ``radius_m`` of the parallelogram {start + s axis + t direction : |s| <=
    half_length_m, 0 <= t <= distance_m}.

    Attributes:
        start: (3,) the capsule centre where the push began.
        axis: (3,) unit axis of the capsule.
        half_length_m: half the distance between the centres of its two caps.
        direction: (3,) unit direction of the push.
        distance_m: how far the centre travelled.
        radius_m: the capsule's radius.
    """

    start: np.ndarray
    axis: np.ndarray
    half_length_m: float
    direction: np.ndarray
    distance_m: float
    radius_m: float

    @staticmethod
    def of(push: Push, pusher: Pusher) -> SweptCapsule:
        """The volume ``pusher`` swept during ``push``."""
        axis = np.asarray(pusher.axis, float)
        return SweptCapsule(
            np.asarray(push.start_m, float),
            axis / np.linalg.norm(axis),
            max(pusher.length_m / 2 - pusher.radius_m, 0.0),
            np.asarray(push.direction, float),
            float(push.distance_m),
            float(pusher.radius_m),
        )

    def moved(self, transform: np.ndarray) -> SweptCapsule:
        """This volume moved by the rigid (4, 4) ``transform``."""
        rotation = transform[:3, :3]
        return dataclasses.replace(
            self,
            start=rotation @ self.start + transform[:3, 3],
            axis=rotation @ self.axis,
            direction=rotation @ self.direction,
        )

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) distance (m) from world points (N, 3) to the swept parallelogram (0 inside it:
        the capsule's surface is at ``radius_m``)."""
        q = np.asarray(points, float).reshape(-1, 3) - self.start
        a, d = self.axis, self.direction
        h, length = self.half_length_m, self.distance_m
        corners = [(-h, 0.0), (h, 0.0), (h, length), (-h, length)]
        best = np.full(len(q), np.inf)
        for (s0, t0), (s1, t1) in zip(corners, corners[1:] + corners[:1], strict=True):
            begin = s0 * a + t0 * d
            edge = (s1 - s0) * a + (t1 - t0) * d
            span = float(edge @ edge)
            along = np.zeros(len(q)) if span == 0 else np.clip((q - begin) @ edge / span, 0, 1)
            gap = np.linalg.norm(q - begin - along[:, None] * edge, axis=1)
            best = np.minimum(best, gap)
        gram = np.array([[a @ a, a @ d], [a @ d, d @ d]])
        if abs(np.linalg.det(gram)) > 1e-9 and length > 0:
            s, t = np.linalg.solve(gram, np.stack([q @ a, q @ d]))
            inside = (np.abs(s) <= h) & (t >= 0) & (t <= length)
            plane = np.linalg.norm(q - s[:, None] * a - t[:, None] * d, axis=1)
            best = np.where(inside, np.minimum(best, plane), best)
        return best

    @functools.cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) lower and upper corners of the axis-aligned box around the volume (m)."""
        ends = self.start + np.array([0.0, self.distance_m])[:, None] * self.direction
        corners = np.concatenate(
            [ends + self.half_length_m * self.axis, ends - self.half_length_m * self.axis]
        )
        return np.stack([corners.min(axis=0) - self.radius_m, corners.max(axis=0) + self.radius_m])

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """(N,) bool: world points (N, 3) inside the swept volume shrunk by ``margin_m``."""
        points = np.asarray(points, float).reshape(-1, 3)
        low, high = self.bounds
        # Most points are nowhere near the pusher: test its bounding box first.
        near = np.flatnonzero(np.all((points >= low) & (points <= high), axis=1))
        inside = np.zeros(len(points), dtype=bool)
        if near.size:
            inside[near] = self.distance(points[near]) <= self.radius_m - margin_m
        return inside


def pushed_through(
    points: np.ndarray,
    motions: dict[int, np.ndarray],
    pushes: tuple[Push, ...] | list[Push],
    pusher: Pusher,
    config: FusionConfig | None = None,
) -> tuple[SweptCapsule, ...]:
    """Volumes the pusher occupied where an object was not, in the object's frame-0 pose.

    Beyond the paper, which uses the pushes only through the simulated motion: the pusher is a
    solid, so wherever it was, the object was not (at that time):

    - a push that did not move the object did not touch it: the whole volume the pusher swept
      was empty of the object, wherever its hidden side is;
    - a push that moved the object ended with the pusher beside it: the capsule at its end
      position (less ``settle_margin_m``, as the object may settle back a little once the
      pusher is withdrawn) was empty of the object at its pose after the push. A push from
      behind thus bounds the hidden back of the object it pushed.

    An object stayed put when its observed points (``points``, (N, 3) world, frame 0) moved less
    than ``static_tolerance_m`` (mean) between its registered poses before and after the push
    (``motions``: frame t -> ``frame0_from_frame`` of ``FusedViews.motions``; frame 0 is the
    identity); a push from or to a frame the object did not register in is skipped. A volume
    that holds the object's own observed points (2 mm inside its surface) contradicts the
    registration (a wrong one, or a swapped id); it is skipped and logged. Each volume is
    returned moved into the object's frame-0 pose by the inverse of its registered motion.
    """
    config = config or FusionConfig()
    points = np.asarray(points, float)
    if len(points) == 0:
        return ()
    poses = {0: np.eye(4), **{t: np.linalg.inv(m) for t, m in motions.items()}}
    result = []
    for push in pushes:
        before, after = poses.get(push.before_frame), poses.get(push.after_frame)
        if before is None or after is None:
            continue
        at_push = _transformed(before, points)
        at_end = _transformed(after, points)
        moved = np.linalg.norm(at_end - at_push, axis=1).mean()
        if moved < config.static_tolerance_m:
            capsule, pose, where = SweptCapsule.of(push, pusher), before, at_push
        else:
            # Moved: where the pusher stopped, the object was not (it settled a little after).
            swept = SweptCapsule.of(push, pusher)
            capsule = dataclasses.replace(
                swept,
                start=np.asarray(push.end_m, float),
                distance_m=0.0,
                radius_m=max(swept.radius_m - config.settle_margin_m, 0.0),
            )
            pose, where = after, at_end
        if capsule.radius_m <= 0:
            continue
        if capsule.contains(where, margin_m=0.002).any():
            logger.info(
                "object's observed points inside the pusher's volume (push from frame %d to "
                "%d); ignored",
                push.before_frame,
                push.after_frame,
            )
            continue
        # In the object's frame-0 pose: where the pusher was, relative to the object.
        result.append(capsule.moved(np.linalg.inv(pose)))
    return tuple(result)


@dataclass(frozen=True, eq=False)
class TrackedFreeSpace:
    """Space seen empty around one object: in frame 0, and in later frames through the object's
    registered motion (beyond the paper, which checks frame 0's free space only).

    A rigid object moved by M_t (frame t from frame 0) holds, in frame t, the points M_t p of
    what it held at p in frame 0. So a frame-0 point p whose image M_t p frame t saw to be empty
    is not part of the object, whatever else stood there in frame 0: a pushed neighbour that
    uncovers the space behind the object shows how far its hidden side can reach, and a pushed
    object that turns shows it in its own later views. Likewise a point p whose image the pusher
    occupied, by the object's motion at the time (``pushed_through``). Frame
    0's map decides where it saw anything (a later frame or a push only turns frame 0's
    *unknown* voxels free), so registration errors cannot contradict what frame 0 saw; the
    maps' surface margin (1 cm) absorbs a few millimetres of registration error. A wrong
    registration does not: a yaw that fits the seen points but sends the hidden side elsewhere
    puts true hidden voxels in this space, for a few objects; kept because it is a plain fact of
    the observations (docs/DESIGN_NOTES.md, "Later frames' free space (on)").

    It answers ``state_at`` and ``grid`` like a ``SpaceMap``, which is all the hypotheses and
    constraints ask of a space.

    Attributes:
        reference: frame 0's map.
        later: per later frame, its map and the object's (4, 4) ``frame_from_frame0`` motion.
        swept: volumes the pusher occupied where the object was not, moved into the object's
            frame-0 pose (``pushed_through``).
    """

    reference: SpaceMap
    later: tuple[tuple[SpaceMap, np.ndarray], ...]
    swept: tuple[SweptCapsule, ...] = ()

    @property
    def grid(self) -> VoxelGrid:
        """Frame 0's voxel grid (world frame, metres)."""
        return self.reference.grid

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """State (N,) of world points (N, 3) at the object's frame-0 pose: FREE where frame 0 or,
        for frame 0's unknown voxels, any later frame saw the moved point's voxel empty or a
        push that left the object in place swept through it."""
        points = np.asarray(points, float)
        states = self.reference.state_at(points)
        hidden = np.flatnonzero(states == UNKNOWN)
        for space, frame_from_frame0 in self.later:
            if hidden.size == 0:
                break
            seen_free = space.state_at(_transformed(frame_from_frame0, points[hidden])) == FREE
            states[hidden[seen_free]] = FREE
            hidden = hidden[~seen_free]
        for capsule in self.swept:
            if hidden.size == 0:
                break
            swept = capsule.contains(points[hidden])
            states[hidden[swept]] = FREE
            hidden = hidden[~swept]
        return states


def tracked_free_spaces(
    fused: FusedViews,
    spaces: list[SpaceMap | None],
    pushes: tuple[Push, ...] | list[Push] = (),
    pusher: Pusher | None = None,
    config: FusionConfig | None = None,
) -> dict[int, TrackedFreeSpace]:
    """Per object id with at least one registered later view (``later_free_space``) or one
    push that swept past it without moving it (``pusher_free_space``, needs ``pushes`` and
    ``pusher``), its ``TrackedFreeSpace``; empty without a frame-0 map. Objects without either
    keep frame 0's map."""
    config = config or FusionConfig()
    if not spaces or spaces[0] is None:
        return {}
    observed = {
        obj.id: np.asarray(obj.points)[np.asarray(obj.pixels) >= 0] for obj in fused.objects
    }
    tracked = {}
    for object_id, motions in fused.motions.items():
        later: tuple = ()
        if config.later_free_space:
            later = tuple(
                (spaces[t], np.linalg.inv(frame0_from_frame))
                for t, frame0_from_frame in sorted(motions.items())
                if spaces[t] is not None
            )
        swept: tuple = ()
        if config.pusher_free_space and pusher is not None and pushes and object_id in observed:
            swept = pushed_through(observed[object_id], motions, pushes, pusher, config)
        if later or swept:
            tracked[object_id] = TrackedFreeSpace(spaces[0], later, swept)
    return tracked
