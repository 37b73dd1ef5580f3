"""Planning and simulating the robot's pushes in a settled pile.

A push aims the vertical capsule at the centre of mass of an object visible in the current
frame, along a random horizontal direction (in a container or drawer, within 60 degrees of the
direction towards the box centre, so that objects are not shoved over the walls). The start is
found by walking back from that centre until the capsule clears every object hull by
``push_clearance_m``, so it starts outside all objects. The capsule's bottom tip is
``pusher_lift_m`` above the table; where no such start exists (a box whose floor is covered),
the capsule is raised in 1 cm steps so that it pushes the upper layer of the pile, its tip
then above the objects below. The whole path stays inside the table/container/drawer region,
at least the capsule radius plus the clearance away from walls. Like a force-limited robot, the
capsule stops early when the object it pushes is jammed (``PileWorld.run_push``); the recorded
distance is the distance travelled.

A candidate is kept when the objects settle afterwards, nothing left its region or penetrates,
and some object moved at least ``min_push_displacement_m``; otherwise another candidate is tried
from the same state. When none moves an object far enough, the valid candidate that moved
objects the most is used.
"""

from __future__ import annotations

import mujoco
import numpy as np

from ipr_shapes.scene import Push
from ipr_shapes.synth.piles import PileWorld, Rejected

#: Step (m) of the searches along a push line.
_SEARCH_STEP_M = 0.004
#: Step (m) by which the capsule is raised when no start is free at table level.
_LIFT_STEP_M = 0.01
#: Shortest useful travel (m) of the capsule beyond its first contact.
_MIN_PUSH_IN_M = 0.01
#: Directions tried per target before drawing a new target.
_DIRECTIONS_PER_TARGET = 4


def _travel_limit(start: np.ndarray, direction: np.ndarray, half: np.ndarray) -> float:
    """Longest travel (m) from ``start`` along ``direction`` inside the centred rectangle."""
    limits = []
    for axis in range(2):
        if abs(direction[axis]) > 1e-9:
            bound = half[axis] if direction[axis] > 0 else -half[axis]
            limits.append((bound - start[axis]) / direction[axis])
    return max(0.0, min(limits))


def _find_start(
    world: PileWorld,
    centre_xy: np.ndarray,
    direction: np.ndarray,
    lift: float,
    probe: mujoco.MjData,
) -> np.ndarray | None:
    """Nearest free capsule centre, raised by ``lift`` (m), on the line back from
    ``centre_xy`` against ``direction``; None when the line leaves the region first."""
    half = world.push_region_half()
    for back in np.arange(0.0, 0.4, _SEARCH_STEP_M):
        candidate = np.array([*(centre_xy - direction[:2] * back), world.pusher_centre_z + lift])
        if np.any(np.abs(candidate[:2]) > half):
            return None
        if world.pusher_clearance(candidate, probe) >= world.config.push_clearance_m:
            return candidate
    return None


def _candidate(
    world: PileWorld, visible: np.ndarray, rng: np.random.Generator, probe: mujoco.MjData
) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """A push (start, direction, distance, contact distance) aimed at a visible object, or
    None when the drawn target offers no feasible one. Starts at table level are preferred
    over raised ones for every direction tried."""
    config = world.config
    target = int(rng.choice(visible))
    centre = world.data.xipos[world.body_ids[target]][:2].copy()
    if world.layout.walls and np.linalg.norm(centre) > 0.03:
        towards_centre = np.arctan2(-centre[1], -centre[0])
        angles = towards_centre + rng.uniform(-np.pi / 3, np.pi / 3, _DIRECTIONS_PER_TARGET)
    else:
        angles = rng.uniform(0.0, 2.0 * np.pi, _DIRECTIONS_PER_TARGET)
    distance = rng.uniform(*config.push_distance_m)
    lifts = [0.0]
    if world.layout.walls:  # on a table the floor around a pile is free: never lifted
        lifts += list(np.arange(_LIFT_STEP_M, world.pile_top() - 0.03 + 1e-9, _LIFT_STEP_M))
    for lift in lifts:
        for angle in angles:
            direction = np.array([np.cos(angle), np.sin(angle), 0.0])
            start = _find_start(world, centre, direction, float(lift), probe)
            if start is None:
                continue
            travel = min(distance, _travel_limit(start, direction, world.push_region_half()))
            contact = next(
                (
                    t
                    for t in np.arange(0.0, travel, _SEARCH_STEP_M)
                    if world.pusher_clearance(start + direction * t, probe) < 0.0
                ),
                None,
            )
            if contact is not None and travel - contact >= 2 * _MIN_PUSH_IN_M:
                return start, direction, float(travel), float(contact)
    return None


def plan_and_push(
    world: PileWorld, visible: np.ndarray, rng: np.random.Generator, before_frame: int
) -> tuple[Push, float]:
    """Find, simulate and keep one push; return it and the largest object displacement (m).

    ``visible`` holds the indices of objects visible in frame ``before_frame``. Raises Rejected
    when no candidate is valid.
    """
    config = world.config
    probe = world.make_probe()
    saved = world.save()
    before = world.poses()[:, :3, 3].copy()
    best: tuple[float, np.ndarray, Push] | None = None
    for _ in range(config.push_attempts):
        found = _candidate(world, visible, rng, probe)
        if found is None:
            continue
        start, direction, distance, contact = found
        speed = float(rng.uniform(*config.push_speed_m_s))
        try:
            travelled, settled = world.run_push(start, direction, distance, speed)
            if not settled or travelled - contact < _MIN_PUSH_IN_M:
                raise Rejected("the push jammed at once or the objects did not settle")
            world.check(require_pile=False)
        except Rejected:
            world.restore(saved)
            continue
        push = Push(before_frame, before_frame + 1, start, direction, float(travelled), speed)
        moved = float(np.linalg.norm(world.poses()[:, :3, 3] - before, axis=1).max())
        if moved >= config.min_push_displacement_m:
            return push, moved
        if best is None or moved > best[0]:
            best = (moved, world.save(), push)
        world.restore(saved)
    if best is None:
        raise Rejected(f"no valid push found before frame {before_frame + 1}")
    world.restore(best[1])
    return best[2], best[0]
