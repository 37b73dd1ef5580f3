"""The exported scene's support plane and the objects' start poses, separated so that nothing
starts interpenetrating.

- **Support**: the plane z = 0 of the world frame (the contract's support, or the plane the
  world frame was built from), unless the lowest object point lies more than
  ``ExportConfig.support_search_m`` from it (a world from camera poses with the table
  elsewhere): then the plane through the lowest object point. ``ExportConfig.support_z_m``
  sets it.
- **Walls**: the convex slabs the inference simulated (``result.json``'s ``walls``), static.
- **Separation**: MuJoCo computes the contacts of the collision pieces at the start poses; an
  object that penetrates the support is lifted by its depth, and of two objects that
  penetrate each other the one whose centre of mass is higher moves out along the contact
  normal by the depth, repeated until no contact is deeper than
  ``ExportConfig.separation_tolerance_m``. Each object's displacement is recorded
  (``ObjectBody.displacement_m``): the size of the voxels' and the smoothing's rounding, about
  a millimetre, where the result's shapes are consistent; centimetres where two objects' most
  probable shapes overlap (each object's output is read from its own marginal, so the pair
  may be one no sample held together).
- **Settling** (``ExportConfig.settle``, on by default): the separated scene is simulated in
  MuJoCo, exactly as exported (collision pieces, masses, friction, timestep), until no
  object moved more than ``settle_distance_m`` or turned more than ``settle_angle_deg`` over
  the last ``settle_window_s`` (at least two windows, at most ``settle_max_s``; poses, not
  speeds, because resting mesh contacts keep a jitter of a few mm/s that goes nowhere); then
  from those poses afresh (zero speeds, no contact history), until a fresh start stays within
  those bounds all the way; the poses of that fresh start are
  exported: the meshes and the inertia are turned in the object frame, whose axes stay the
  world's. Each object's displacement and rotation are recorded (``displacement_m``,
  ``rotation_deg``; the manifest's ``settling``). This is a last resort, not a correction of
  the shapes: the result's shapes are not a scene at rest on their own (overlapping most
  probable shapes, objects that leaned on walls a result does not carry, shapes the
  inference scored as unstable but the most probable still); without it such a scene starts
  moving as soon as a simulator loads it (docs/experiments/2026-11-26-export-rest.md).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ipr_shapes.export.mjcf import mjcf_document
from ipr_shapes.export.model import ExportConfig, ObjectBody

log = logging.getLogger(__name__)


#: Poses are compared this often while settling (s).
SETTLE_CHECK_S = 0.01


@dataclass(frozen=True, eq=False)
class SceneBodies:
    """The exported scene: the support plane z = ``support_z_m`` (normal +z), the objects and
    the static walls (``walls``: per wall the (V, 3) vertices of its convex slab, m, world).

    ``support_source`` says how the height was chosen; ``max_penetration_m`` is the deepest
    contact left after separation (0 when every start pose is clear); ``settle_s`` how long
    the scene was simulated to settle (0: not settled) and ``at_rest`` whether it came to
    rest within ``ExportConfig.settle_max_s``.
    """

    support_z_m: float
    support_source: str
    objects: tuple[ObjectBody, ...]
    max_penetration_m: float
    settle_s: float = 0.0
    at_rest: bool = True
    walls: tuple[np.ndarray, ...] = ()


def scene_bodies(
    objects: Sequence[ObjectBody],
    config: ExportConfig | None = None,
    *,
    walls: Sequence[np.ndarray] = (),
) -> SceneBodies:
    """The support plane, the walls ((V, 3) slab vertices each, m, world) and the objects with
    separated start poses (module doc)."""
    config = config or ExportConfig()
    walls = tuple(np.asarray(wall, dtype=np.float64) for wall in walls)
    lowest = min(
        (float(body.surface.vertices[:, 2].min() + body.position_m[2]) for body in objects),
        default=0.0,
    )
    if config.support_z_m is not None:
        support_z, source = float(config.support_z_m), "given"
    elif abs(lowest) <= config.support_search_m:
        support_z, source = 0.0, "world z = 0"
    else:
        support_z, source = lowest, "lowest object point"
    positions, depth = separate(objects, support_z, config, walls=walls)
    moved = tuple(
        replace(
            body,
            position_m=position,
            displacement_m=body.displacement_m + (position - body.position_m),
        )
        for body, position in zip(objects, positions, strict=True)
    )
    if not config.settle or not moved:
        return SceneBodies(support_z, source, moved, depth, walls=walls)
    settled, seconds, at_rest = settle(moved, support_z, config, walls=walls)
    if not at_rest:
        log.warning(
            "the exported scene did not come to rest within %.1f s; exporting where it was",
            config.settle_max_s,
        )
    return SceneBodies(support_z, source, settled, depth, seconds, at_rest, walls)


def settle(
    objects: Sequence[ObjectBody],
    support_z_m: float,
    config: ExportConfig,
    *,
    walls: Sequence[np.ndarray] = (),
) -> tuple[tuple[ObjectBody, ...], float, bool]:
    """The objects at the poses the scene settles in (module doc), the simulated time (s) and
    whether it came to rest within ``config.settle_max_s``.

    Each round starts afresh (zero speeds, no contact history, the meshes turned): the scene
    a simulator loads from the files. The poses exported are those of the first round that
    stayed within the bounds all the way (a scene at rest as the result put it keeps its
    poses); a round that did not hands its end poses to the next.
    """
    start = tuple(objects)
    current = start
    seconds = 0.0
    at_rest = False
    while not at_rest and seconds < config.settle_max_s - 1e-9:
        settled, spent, quiet, farthest = _settle_once(
            current, support_z_m, config, config.settle_max_s - seconds, walls
        )
        seconds += spent
        if settled is current:  # exploded: keep the last poses
            break
        at_rest = bool(
            quiet
            and farthest[0] < config.settle_distance_m
            and farthest[1] < config.settle_angle_deg
        )
        if not at_rest:
            current = settled
    # A body no round moved is where the result put it: exactly no turn (its axes times their
    # own transpose are the identity only to rounding, which arccos blows up to 1e-6 degrees).
    total = tuple(
        body
        if body is first
        else replace(body, rotation_deg=_angle_deg(body.principal_axes @ first.principal_axes.T))
        for first, body in zip(start, current, strict=True)
    )
    return total, seconds, at_rest


def _angle_deg(rotation: np.ndarray) -> float:
    """The angle (degrees) of a (3, 3) rotation."""
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1.0, 1.0))))


def _settle_once(
    objects: tuple[ObjectBody, ...],
    support_z_m: float,
    config: ExportConfig,
    max_s: float,
    walls: Sequence[np.ndarray] = (),
) -> tuple[tuple[ObjectBody, ...], float, bool, tuple[float, float]]:
    """Simulate the objects from rest until the window criterion holds (module doc) or
    ``max_s``; the turned objects (``objects`` itself when the simulation exploded), the
    simulated time, whether the criterion held, and the farthest any object got from its
    start (m, degrees) on the way."""
    import mujoco

    xml, assets = mjcf_document(
        objects, support_z_m, config, collision_only=True, embed=True, walls=walls
    )
    model = mujoco.MjModel.from_xml_string(xml, assets)
    data = mujoco.MjData(model)
    bodies = [model.body(body.name).id for body in objects]
    check = max(1, round(SETTLE_CHECK_S / model.opt.timestep))
    window = max(1, round(config.settle_window_s / (check * model.opt.timestep)))
    limit = max(check, round(max_s / model.opt.timestep))
    cosine = np.cos(np.radians(config.settle_angle_deg) / 2)
    mujoco.mj_forward(model, data)
    history = [(data.xpos[bodies].copy(), data.xquat[bodies].copy())]
    start_position, start_quaternion = history[0]
    farthest = np.zeros(2)
    steps = 0
    at_rest = False
    while steps < limit and not at_rest:
        mujoco.mj_step(model, data, check)
        steps += check
        if (
            not np.isfinite(data.qpos).all()
            or data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
        ):
            log.warning("the exported scene exploded while settling; exporting it unsettled")
            return objects, steps * float(model.opt.timestep), False, (np.inf, np.inf)
        history.append((data.xpos[bodies].copy(), data.xquat[bodies].copy()))
        away = np.linalg.norm(data.xpos[bodies] - start_position, axis=1).max()
        half = np.abs(np.sum(data.xquat[bodies] * start_quaternion, axis=1)).min()
        angle = float(np.degrees(2 * np.arccos(np.clip(half, -1.0, 1.0))))
        farthest = np.maximum(farthest, (away, angle))
        if len(history) > window:
            position, quaternion = history.pop(0)
            moved = np.linalg.norm(data.xpos[bodies] - position, axis=1)
            turned_half = np.abs(np.sum(data.xquat[bodies] * quaternion, axis=1))
            # Not before two windows: a shape balanced on an edge leaves its pose slowly, then
            # fast (exponentially); the first window alone can miss the start.
            at_rest = (
                steps * model.opt.timestep >= 2 * config.settle_window_s - 1e-9
                and bool((moved < config.settle_distance_m).all())
                and bool((turned_half > cosine).all())
            )
    settled = []
    for body, index in zip(objects, bodies, strict=True):
        rotation = data.xmat[index].reshape(3, 3).copy()
        position = data.xpos[index].copy()
        settled.append(turned(body, rotation, position))
    return tuple(settled), steps * float(model.opt.timestep), at_rest, tuple(farthest)


def turned(body: ObjectBody, rotation: np.ndarray, position: np.ndarray) -> ObjectBody:
    """``body`` turned by ``rotation`` (3, 3, world axes, about its centre of mass) and placed
    with its centre of mass at ``position`` (3,): the meshes and the inertia turn in the
    object frame, whose axes stay the world's."""
    transform = np.eye(4)
    transform[:3, :3] = rotation
    surface = body.surface.copy()
    surface.apply_transform(transform)
    pieces = []
    for piece in body.collision:
        piece = piece.copy()
        piece.apply_transform(transform)
        pieces.append(piece)
    return replace(
        body,
        surface=surface,
        collision=tuple(pieces),
        position_m=np.asarray(position, dtype=np.float64),
        displacement_m=body.displacement_m + (position - body.position_m),
        inertia_kg_m2=rotation @ body.inertia_kg_m2 @ rotation.T,
        principal_axes=rotation @ body.principal_axes,
    )


def separate(
    objects: Sequence[ObjectBody],
    support_z_m: float,
    config: ExportConfig,
    *,
    walls: Sequence[np.ndarray] = (),
) -> tuple[np.ndarray, float]:
    """Start positions (N, 3) with no contact deeper than the tolerance (module doc), and the
    deepest contact left (m, 0 if none)."""
    import mujoco

    positions = np.array([body.position_m for body in objects], dtype=np.float64).reshape(-1, 3)
    if not objects:
        return positions, 0.0
    xml, assets = mjcf_document(
        objects, support_z_m, config, collision_only=True, embed=True, walls=walls
    )
    model = mujoco.MjModel.from_xml_string(xml, assets)
    data = mujoco.MjData(model)
    body_of_geom = np.full(model.ngeom, -1, dtype=np.int64)
    for index, body in enumerate(objects):
        for geom in range(model.ngeom):
            if model.geom_bodyid[geom] == model.body(body.name).id:
                body_of_geom[geom] = index
    address = [int(model.jnt_qposadr[model.body(body.name).jntadr[0]]) for body in objects]
    push = 2e-5  # beyond the depth, so that the contact is gone rather than just touching
    depth = 0.0
    for _ in range(config.separation_iterations + 1):
        for index, start in enumerate(address):
            data.qpos[start : start + 3] = positions[index]
        mujoco.mj_forward(model, data)
        moves: dict[int, tuple[float, np.ndarray]] = {}
        depth = 0.0
        for contact in data.contact[: data.ncon]:
            penetration = -float(contact.dist)
            if penetration <= 0:
                continue
            depth = max(depth, penetration)
            if penetration <= config.separation_tolerance_m:
                continue
            first, second = (int(body_of_geom[g]) for g in contact.geom)
            normal = np.asarray(contact.frame[:3], dtype=np.float64)  # from geom 1 to geom 2
            if first < 0 and second < 0:
                continue
            if first < 0:
                mover, direction = second, normal
            elif second < 0:
                mover, direction = first, -normal
            elif positions[second, 2] >= positions[first, 2]:
                mover, direction = second, normal
            else:
                mover, direction = first, -normal
            if penetration > moves.get(mover, (0.0, None))[0]:
                moves[mover] = (penetration, direction)
        if not moves:
            break
        for mover, (penetration, direction) in moves.items():
            positions[mover] += direction * (penetration + push)
    return positions, depth
