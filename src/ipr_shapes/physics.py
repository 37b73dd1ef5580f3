"""The physics world of a joint shape model (paper Sec. IV-E): MuJoCo simulation of gravity and
of the robot's pushes, and depth/object-id rendering of the simulated scene.

World frame (``ipr_shapes.scene``): metres, the support plane's normal is "up"; gravity acts along
``-support.normal``. A joint model is a list of closed convex meshes in the world frame at their
frame-0 poses (``ShapeHypothesis`` vertices/faces).

- Objects: one free body per shape, its collision geom the mesh (MuJoCo collides the convex
  hull), uniform density ``density_kg_m3`` and friction ``friction`` for every object (the paper
  found results insensitive to both). The body frame starts at the shape's vertex centroid with
  the world's orientation, so a body's pose is directly the object's motion from frame 0.
- Static geometry: the support as a large box whose top face is the support plane; each wall as
  the convex slab of its observed points' outline, ``thickness_m`` deep behind its visible face
  (at least ``wall_min_thickness_m``). The pusher, and static geometry unless
  ``render_static``, are in geom group 3, which the renderer hides.
- Static shapes (``Body.dynamic`` False) are welded to the world: used as context when only some
  objects' stability matters (Algorithm 2's partial scenes).
- Candidates (``Body.candidate``): free bodies that collide with everything static but not with
  each other (contype 2, conaffinity 1), so that all hypotheses of one object are tested for
  stability in one simulation instead of one model each.
- The pusher is a mocap capsule (``ipr_shapes.scene.Pusher``) parked far away; a push moves its centre
  from ``start_m`` along ``direction`` at ``speed_m_s`` for ``distance_m``, stopping early like a
  force-limited robot when it sinks more than ``push_stop_intrusion_m`` into an object (the
  object is jammed), is withdrawn, and the objects settle. The pusher's contacts have their own
  stiffness (``PhysicsConfig.pusher_timeconst_s``, MuJoCo's soft default unless set), and the
  push its own step (``push_timestep_s``).
- A simulation *explodes* when a state becomes non-finite or MuJoCo reports an instability; an
  object is *flung* when it moves more than ``flung_m``. Callers score such a joint model (or
  such a stability candidate) as impossible.

MuJoCo is deterministic: the same joint model and actions give bit-identical results.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ipr_shapes.checks import Checks, Interval, Options, Pair, Predicate, check_fields
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.rendering import (
    PinholeCamera,
    Renderer,
    add_pinhole_camera,
    configure_visual,
)
from ipr_shapes.scene import Push, Pusher

#: Geom group of static geometry and the pusher; ``ipr_shapes.rendering.Renderer`` draws groups 0-2.
HIDDEN_GROUP = 3
#: Where the pusher waits between pushes (m, world).
PUSHER_PARK_M = np.array([0.0, 0.0, 50.0])
#: A push into a world at rest is simulated from where the pusher comes this close to a
#: shape (m); the steps before are skipped (``World.push``).
APPROACH_MARGIN_M = 0.005


@dataclass(frozen=True)
class PhysicsConfig:
    """Physical parameters of the simulated scenes (one set for every object, as in the paper).

    Attributes:
        timestep_s: integration step (s). 8 ms: half the steps of 4 ms, and the replayed
            pushes no further from the data (docs/DESIGN_NOTES.md, "Time step");
            MuJoCo wants a contact's time constant (0.02 s) at least two steps.
        density_kg_m3: uniform object density (kg/m^3); 400 is a typical packaged household
            object (YCB's boxes and bottles span roughly 100-1200).
        friction: sliding friction of every contact (MuJoCo takes the larger of the two geoms').
        torsional_friction: torsional friction (m).
        rolling_friction_m: rolling friction (m), a little, so that round shapes come to rest.
        gravity_m_s2: magnitude of gravity, along ``-support.normal``.
        settle_max_s: longest settling after the initial placement and after each push (s).
        settle_linear_m_s: every object slower than this (and ``settle_angular_rad_s``) is
            settled.
        settle_angular_rad_s: angular speed threshold of settling (rad/s).
        stability_s: simulated time of a stability test (Algorithm 2's exploration step, s):
            long enough for an unsupported shape to fall ~0.4 m or start toppling visibly.
        push_stop_intrusion_m: the pusher stops when it sinks deeper than this into an object.
        push_timestep_s: integration step while the pusher moves (s); settling after the
            push returns to ``timestep_s``. MuJoCo raises a contact time constant below two
            steps to two steps, so this bounds how stiff the pusher's contact can be.
        pusher_timeconst_s: time constant (s) of the pusher's contacts (MuJoCo ``solref``'s
            first number). 0.02 is MuJoCo's soft default, the objects' own; a position-
            controlled robot's tool does not yield, which ``STIFF_PUSHER`` models (0.004 s at
            a 0.002 s push step, the generator's). The default stays soft: the stiff pusher
            did not bring replayed pushes closer to the data (docs/DESIGN_NOTES.md, "The
            pusher's contact").
        pusher_dampratio: damping ratio of the pusher's contacts (``solref``'s second number;
            1: critically damped, no bounce).
        pusher_impedance: (dmin, dmax) of the pusher's contacts (``solimp``, its width 1 mm as
            MuJoCo's default): the share of the contact force the constraint delivers at zero
            and at 1 mm of intrusion; nearer 1 yields less.
        push_max_s: longest simulated push (s): a slower push is replayed at distance /
            push_max_s, so that any push costs a bounded number of steps (the pusher is
            position-controlled and the objects quasi-static at either speed). 1 s: a robot's
            push of 4-6 cm/s is replayed at up to 12 cm/s, in half the steps and no further
            from the data.
        flung_m: an object moving further than this (m) means the simulation exploded.
        support_half_extent_m: half side of the support box (m).
        wall_min_thickness_m: thinnest wall slab (m); thinner slabs let objects tunnel.
        condim: MuJoCo contact dimensionality of every contact: 6 (sliding, torsional and
            rolling friction: 6 constraint rows per contact with elliptic cones), 4 (no
            rolling), 3 (sliding only) or 1 (frictionless).
        cone: friction cone, "elliptic" (exact) or "pyramidal" (MuJoCo's linearised).
        solver: MuJoCo's constraint solver, "newton", "cg" or "pgs".
        solver_iterations: most solver iterations per step.
        solver_tolerance: the solver stops when its relative cost improvement is below this.
        ls_iterations: most line-search iterations per solver iteration (Newton and CG).
        max_hull_vertices: collision hull of each shape with at most this many vertices
            (MuJoCo's ``maxhullvert``; the rendered mesh is the shape's own); 0: the whole hull.
        multiccd: several contact points per convex pair (MuJoCo's multiccd), so that a face
            resting on a face is held by a manifold, not one point.
        nativeccd: MuJoCo's own convex collision (False: libccd).
    """

    CHECKS: ClassVar[Checks] = {
        "timestep_s": Interval(0, None, closed="neither"),
        "density_kg_m3": Interval(0, None, closed="neither"),
        "friction": Interval(0, 5),
        "torsional_friction": Interval(0, None),
        "rolling_friction_m": Interval(0, None),
        "gravity_m_s2": Interval(0, None, closed="neither"),
        "settle_max_s": Interval(0, None, closed="neither"),
        "settle_linear_m_s": Interval(0, None),
        "settle_angular_rad_s": Interval(0, None),
        "stability_s": Interval(0, None, closed="neither"),
        "push_stop_intrusion_m": Interval(0, None),
        "push_timestep_s": Interval(0, None, closed="neither"),
        "pusher_timeconst_s": Interval(0, None, closed="neither"),
        "pusher_dampratio": Interval(0, None, closed="neither"),
        "pusher_impedance": Pair(Interval(0.0001, 0.9999)),
        "push_max_s": Interval(0, 600, closed="right"),
        "flung_m": Interval(0, None, closed="neither"),
        "support_half_extent_m": Interval(0, None, closed="neither"),
        "wall_min_thickness_m": Interval(0, None),
        "condim": Options(1, 3, 4, 6),
        "cone": Options("elliptic", "pyramidal"),
        "solver": Options("newton", "cg", "pgs"),
        "solver_iterations": Interval(1, None, integer=True),
        "solver_tolerance": Interval(0, None),
        "ls_iterations": Interval(1, None, integer=True),
        "max_hull_vertices": Predicate(
            lambda v: type(v) is int and (v == 0 or v >= 4), "0 or an integer of at least 4"
        ),
        "multiccd": Options(True, False),
        "nativeccd": Options(True, False),
    }

    timestep_s: float = 0.008
    density_kg_m3: float = 400.0
    friction: float = 1.0
    torsional_friction: float = 0.005
    rolling_friction_m: float = 0.002
    gravity_m_s2: float = 9.81
    settle_max_s: float = 1.0
    settle_linear_m_s: float = 0.005
    settle_angular_rad_s: float = 0.05
    stability_s: float = 0.3
    push_stop_intrusion_m: float = 0.01
    push_timestep_s: float = 0.008
    pusher_timeconst_s: float = 0.02
    pusher_dampratio: float = 1.0
    pusher_impedance: tuple[float, float] = (0.9, 0.95)
    push_max_s: float = 1.0
    flung_m: float = 0.5
    support_half_extent_m: float = 2.0
    wall_min_thickness_m: float = 0.01
    condim: int = 6
    cone: Literal["elliptic", "pyramidal"] = "elliptic"
    solver: Literal["newton", "cg", "pgs"] = "newton"
    solver_iterations: int = 100
    solver_tolerance: float = 1e-8
    ls_iterations: int = 50
    max_hull_vertices: int = 0
    multiccd: bool = True
    nativeccd: bool = True

    def __post_init__(self) -> None:
        check_fields(self)


#: ``PhysicsConfig`` settings of a stiff, position-controlled pusher (the generator's pusher
#: contact at its 2 ms step): ``dataclasses.replace(config, **STIFF_PUSHER)``.
STIFF_PUSHER = {
    "push_timestep_s": 0.002,
    "pusher_timeconst_s": 0.004,
    "pusher_impedance": (0.95, 0.99),
}


@dataclass(frozen=True, eq=False)
class Body:
    """One object shape in a physics world.

    Attributes:
        vertices: (V, 3) world vertices at the frame-0 pose (m); the shape is their convex hull.
        faces: (F, 3) triangles (only used for rendering).
        dynamic: False welds the shape to the world (context of a stability test).
        candidate: a free body that does not collide with other candidates (stability tests).
        switchable: a dynamic body compiled so that ``World.hold`` can take it out of the
            simulation (a stability test's candidate frozen once at rest or screened out).
        rigid_group: dynamic shapes with the same non-negative number are one rigid body
            (welded together, as a stability test of a group of objects needs); -1: its own.
    """

    vertices: np.ndarray
    faces: np.ndarray
    dynamic: bool = True
    candidate: bool = False
    switchable: bool = False
    rigid_group: int = -1


@dataclass(eq=False)
class World:
    """A compiled MuJoCo model of a joint model and its state.

    ``bodies`` the shapes; ``body_ids[k]`` the MuJoCo body of dynamic shape k (-1 for static);
    ``object_of_geom`` (ngeom,) the index into ``bodies`` of each geom (-1: static geometry,
    pusher); ``cameras`` the names of the cameras added (one per image to render).
    """

    model: Any
    data: Any
    bodies: tuple[Body, ...]
    body_ids: np.ndarray
    object_of_geom: np.ndarray
    config: PhysicsConfig
    cameras: tuple[str, ...] = ()
    pusher_geom: int = -1
    pusher_mocap: int = -1
    origins: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    exploded: bool = False
    at_rest: bool = False
    initial_com: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    shape_geoms: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int32))
    local_boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))

    # ----------------------------------------------------------------------------------------
    # Reuse: one compiled world for many stability tests

    def reset(self) -> None:
        """Back to the compiled frame-0 state (poses, zero velocities, no warm start), not
        exploded; the switches (``set_colliding``, ``hold``) stay as they are."""
        mujoco.mj_resetData(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)
        self.exploded = False
        self.at_rest = False

    def set_colliding(self, k: int, on: bool) -> None:
        """Switch shape k's collisions on (as compiled) or off (it then touches nothing): a
        static shape switched off is absent, so one compiled world serves many contexts."""
        geom = self.shape_geoms[k]
        contype, conaffinity = self.contacts[k] if on else (0, 0)
        self.model.geom_contype[geom] = contype
        self.model.geom_conaffinity[geom] = conaffinity

    def set_friction(self, sliding: float) -> None:
        """Give every geom (shapes, support, walls, pusher) the sliding friction ``sliding``,
        so every contact has it (MuJoCo takes the larger of two geoms'): a joint model
        replayed under another friction without recompiling (``ipr_shapes.inference``'s
        friction search)."""
        self.model.geom_friction[:, 0] = sliding

    def hold(self, k: int, held: bool = True) -> None:
        """Take ``switchable`` body k out of the simulation where it is (no collisions, gravity
        compensated, at rest) or put it back (``held`` False). A held body moves no further
        and costs the others nothing but its idle degrees of freedom."""
        body = self.body_ids[k]
        if body < 0 or not self.bodies[k].switchable:
            raise ValueError(f"shape {k} is not a switchable dynamic body")
        self.set_colliding(k, not held)
        self.model.body_gravcomp[body] = 1.0 if held else 0.0
        if held:
            start = self.model.body_dofadr[body]
            self.data.qvel[start : start + 6] = 0.0

    def settle_each(
        self, shapes: Sequence[int], max_s: float, swept: np.ndarray | None = None
    ) -> np.ndarray:
        """Step until each of ``shapes`` (switchable dynamic bodies) is slower than the settle
        thresholds, holding each (``hold``) as soon as it is, checked every 50 ms as in
        ``settle``, or until ``max_s`` passed; a body's distances are then measured where it
        came to rest. Returns (len(shapes),) bool: which came to rest (False for all when the
        world exploded). Why: one shape still moving no longer keeps every other one
        simulated (and its contacts solved) to the end of the test.

        ``swept`` (len(shapes), 2, 3), when given, receives each shape's swept box (m, world):
        the union of its axis-aligned boxes (``shape_boxes``) at every step, from the start
        to where it came to rest. MuJoCo detects contacts at the steps' poses only, so a
        shape whose swept box no other shape's box enters touched none of them (the
        stability cache of ``ipr_shapes.inference.sampler`` reuses its result in any context
        that agrees inside that box). Stepping then goes one step per call (the same steps)."""
        config = self.config
        check_every = max(1, int(round(0.05 / config.timestep_s)))
        steps = int(np.ceil(max_s / config.timestep_s))
        shapes = list(shapes)
        moving = list(range(len(shapes)))
        rested = np.zeros(len(shapes), dtype=bool)
        dofs = self.model.body_dofadr[self.body_ids[shapes]] if shapes else np.zeros(0, int)
        if swept is not None and shapes:
            swept[:] = self.shape_boxes(shapes)
            positions = np.empty((check_every, len(shapes), 3))
            rotations = np.empty((check_every, len(shapes), 9))
        for _ in range(0, steps, check_every):
            if not moving:
                break
            if swept is None:
                mujoco.mj_step(self.model, self.data, nstep=check_every)
            else:
                moved = [shapes[m] for m in moving]
                ids = self.body_ids[moved]
                count = len(moved)
                for step in range(check_every):
                    mujoco.mj_step(self.model, self.data)
                    # After mj_step, xpos and xmat are the pose its collisions were found at.
                    np.take(self.data.xpos, ids, axis=0, out=positions[step, :count])
                    np.take(self.data.xmat, ids, axis=0, out=rotations[step, :count])
                low, high = self._boxes_at(moved, positions[:, :count], rotations[:, :count])
                swept[moving, 0] = np.minimum(swept[moving, 0], low.min(axis=0))
                swept[moving, 1] = np.maximum(swept[moving, 1], high.max(axis=0))
            if not self._check():
                return np.zeros(len(shapes), dtype=bool)
            velocity = self.data.qvel[dofs[moving, None] + np.arange(6)]
            linear = np.linalg.norm(velocity[:, :3], axis=1)
            angular = np.linalg.norm(velocity[:, 3:], axis=1)
            still = (linear < config.settle_linear_m_s) & (angular < config.settle_angular_rad_s)
            for position in np.flatnonzero(still):
                rested[moving[position]] = True
                self.hold(shapes[moving[position]])
            moving = [m for m, s in zip(moving, still, strict=True) if not s]
        return rested

    def shape_boxes(self, shapes: Sequence[int]) -> np.ndarray:
        """(len(shapes), 2, 3) axis-aligned boxes (m, world) of dynamic ``shapes`` where they
        are now: each shape's frame-0 box about its body origin, turned and moved with the
        body (the box of the turned box: it contains the shape; exact at frame 0)."""
        ids = self.body_ids[np.asarray(shapes, dtype=np.int64)]
        low, high = self._boxes_at(shapes, self.data.xpos[ids][None], self.data.xmat[ids][None])
        return np.stack([low[0], high[0]], axis=1)

    def _boxes_at(self, shapes: Sequence[int], positions: np.ndarray, rotations: np.ndarray):
        """The boxes of ``shapes`` at T poses, body positions (T, S, 3) and rotations (T, S, 9)
        as ``data.xpos`` and ``data.xmat`` hold them: their low and high corners (T, S, 3)."""
        local = self.local_boxes[np.asarray(shapes, dtype=np.int64)]
        rotation = rotations.reshape(*rotations.shape[:2], 3, 3)
        centre = positions + np.matmul(rotation, local.mean(axis=1)[:, :, None])[..., 0]
        half = np.matmul(np.abs(rotation), ((local[:, 1] - local[:, 0]) / 2)[:, :, None])[..., 0]
        return centre - half, centre + half

    # ----------------------------------------------------------------------------------------
    # State

    def poses(self) -> np.ndarray:
        """(n, 4, 4) world transforms moving each shape from its frame-0 pose to where it is
        now (identity for static shapes)."""
        result = np.tile(np.eye(4), (len(self.bodies), 1, 1))
        dynamic = np.flatnonzero(self.body_ids >= 0)
        ids = self.body_ids[dynamic]
        rotation = self.data.xmat[ids].reshape(-1, 3, 3)
        result[dynamic, :3, :3] = rotation
        result[dynamic, :3, 3] = self.data.xpos[ids] - np.einsum(
            "kij,kj->ki", rotation, self.origins[dynamic]
        )
        return result

    def displacements(self) -> np.ndarray:
        """(n,) mean distance (m) the vertices of each shape moved since frame 0 (0 for static
        shapes; inf for flung shapes, and for all when the simulation exploded)."""
        if self.exploded:
            return np.full(len(self.bodies), np.inf)
        poses = self.poses()
        moved = np.zeros(len(self.bodies))
        for k, body in enumerate(self.bodies):
            if self.body_ids[k] < 0:
                continue
            now = body.vertices @ poses[k, :3, :3].T + poses[k, :3, 3]
            moved[k] = float(np.linalg.norm(now - body.vertices, axis=1).mean())
        moved[self.flung()] = np.inf
        return moved

    def drops(self) -> np.ndarray:
        """(n,) how far (m, >= 0) the centre of mass of each shape fell along gravity since
        frame 0: the potential energy it released per unit mass and g (0 for static shapes;
        inf for flung shapes, and for all when the simulation exploded). Unlike
        ``displacements`` it ignores the sideways shove that resolves a small initial overlap."""
        return np.maximum(self.vertical_motions(), 0.0)

    def vertical_motions(self) -> np.ndarray:
        """(n,) how far (m) the centre of mass of each shape moved along gravity since frame
        0, signed: > 0 fell, < 0 rose (lifted out of an initial overlap); 0 for static
        shapes, inf for flung shapes, and for all when the simulation exploded."""
        if self.exploded:
            return np.full(len(self.bodies), np.inf)
        gravity = np.asarray(self.model.opt.gravity, float)
        down = gravity / max(np.linalg.norm(gravity), 1e-12)
        result = np.zeros(len(self.bodies))
        dynamic = np.flatnonzero(self.body_ids >= 0)
        moved = self.data.xipos[self.body_ids[dynamic]] - self.initial_com[dynamic]
        result[dynamic] = moved @ down
        result[self.flung()] = np.inf
        return result

    def _check(self) -> bool:
        """Mark the world exploded when the state is not finite or MuJoCo found it unstable."""
        if self.exploded:
            return False
        data = self.data
        unstable = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number) > 0
        if unstable or not (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()):
            self.exploded = True
            return False
        return True

    def flung(self) -> np.ndarray:
        """(n,) bool: dynamic shapes whose centre moved more than ``flung_m`` (all True when
        the simulation exploded)."""
        if self.exploded:
            return np.ones(len(self.bodies), dtype=bool)
        result = np.zeros(len(self.bodies), dtype=bool)
        dynamic = np.flatnonzero(self.body_ids >= 0)
        moved = np.linalg.norm(
            self.data.xpos[self.body_ids[dynamic]] - self.origins[dynamic], axis=1
        )
        result[dynamic] = moved > self.config.flung_m
        return result

    # ----------------------------------------------------------------------------------------
    # Simulation

    def step(self, seconds: float) -> bool:
        """Integrate ``seconds``; False (and ``exploded``) when the simulation exploded."""
        self.at_rest = False
        steps = max(1, int(round(seconds / self.config.timestep_s)))
        check_every = max(1, int(round(0.05 / self.config.timestep_s)))
        for start in range(0, steps, check_every):
            mujoco.mj_step(self.model, self.data, nstep=min(check_every, steps - start))
            if not self._check():
                return False
        return True

    def settle(self, max_s: float | None = None) -> bool:
        """Step until every dynamic body is slower than the settle thresholds (True) or
        ``max_s`` (default ``settle_max_s``) passed (False). Exploded worlds return False."""
        config = self.config
        max_s = config.settle_max_s if max_s is None else max_s
        check_every = max(1, int(round(0.05 / config.timestep_s)))
        steps = int(np.ceil(max_s / config.timestep_s))
        dofs = self.model.nv
        self.at_rest = False
        for _ in range(0, steps, check_every):
            mujoco.mj_step(self.model, self.data, nstep=check_every)
            if not self._check():
                return False
            if dofs == 0:
                self.at_rest = True
                return True
            velocity = self.data.qvel.reshape(-1, 6)
            if (
                np.linalg.norm(velocity[:, :3], axis=1).max() < config.settle_linear_m_s
                and np.linalg.norm(velocity[:, 3:], axis=1).max() < config.settle_angular_rad_s
            ):
                self.at_rest = True
                return True
        return False

    def _steps_before_contact(self, start: np.ndarray, direction: np.ndarray, steps: int,
                              step_m: float) -> int:  # fmt: skip
        """How many of a push's ``steps`` (``step_m`` apart along ``direction`` from
        ``start``) the pusher makes before it comes within ``APPROACH_MARGIN_M`` of a shape
        (all of them when it never does), in a world at rest (0 otherwise): until the pusher
        arrives, stepping a world at rest changes nothing, so those steps are skipped (the
        early stop of ``settle``, before a push). Marches along the path by each exact
        pusher-shape distance (``mujoco.mj_geomDistance``), which the pusher cannot cover
        without touching."""
        if not self.at_rest or self.pusher_mocap < 0:
            return 0
        model, data = self.model, self.data
        geoms = [int(self.shape_geoms[k]) for k in np.flatnonzero(self.body_ids >= 0)]
        length = steps * step_m
        reach = 0.5  # m: farther than any push travels
        clear = 0.0
        while clear < length:
            data.mocap_pos[self.pusher_mocap] = start + direction * clear
            mujoco.mj_kinematics(model, data)
            gap = min(
                (mujoco.mj_geomDistance(model, data, self.pusher_geom, g, reach, None)
                 for g in geoms),
                default=reach,
            )  # fmt: skip
            if gap <= APPROACH_MARGIN_M:
                break
            clear += gap - APPROACH_MARGIN_M / 2
        data.mocap_pos[self.pusher_mocap] = start
        mujoco.mj_kinematics(model, data)
        return min(steps, int(clear // step_m))

    def push(self, push: Push) -> float:
        """Replay one push (module doc) and let the objects settle; return the distance (m)
        the pusher travelled. The world may be ``exploded`` afterwards."""
        if self.pusher_mocap < 0:
            raise ValueError("this world has no pusher")
        config = self.config
        data = self.data
        start = np.asarray(push.start_m, float)
        direction = np.asarray(push.direction, float)
        data.mocap_pos[self.pusher_mocap] = start
        speed = max(push.speed_m_s, push.distance_m / config.push_max_s)
        timestep = config.push_timestep_s
        steps = max(1, int(np.ceil(push.distance_m / speed / timestep)))
        step_m = timestep * speed
        skipped = self._steps_before_contact(start, direction, steps, step_m)
        travelled = min(skipped * step_m, push.distance_m)
        if skipped < steps:
            self.at_rest = False
        check_every = max(1, int(round(0.1 / timestep)))
        self.model.opt.timestep = timestep
        # Per step only what the early stop needs (cheap numpy: a step costs 0.1-0.4 ms).
        model, mocap, pusher = self.model, data.mocap_pos, self.pusher_geom
        intrusion = config.push_stop_intrusion_m
        try:
            for step in range(skipped + 1, steps + 1):
                travelled = min(step * timestep * speed, push.distance_m)
                mocap[self.pusher_mocap] = start + direction * travelled
                mujoco.mj_step(model, data)
                if step % check_every == 0 and not self._check():
                    return travelled
                count = data.ncon
                if count:
                    contact = data.contact
                    geom = contact.geom[:count]
                    touching = (geom[:, 0] == pusher) | (geom[:, 1] == pusher)
                    if touching.any() and -contact.dist[:count][touching].min() > intrusion:
                        break
        finally:
            self.model.opt.timestep = config.timestep_s
            data.mocap_pos[self.pusher_mocap] = PUSHER_PARK_M
        if self._check():
            self.settle()
        return travelled

    # ----------------------------------------------------------------------------------------
    # Rendering

    def render(self, renderer: Renderer, camera: str) -> tuple[np.ndarray, np.ndarray]:
        """Depth (H, W) float32 m (0: nothing drawn) and the index into ``bodies`` (H, W)
        int32 of the front-most shape (-1: nothing, -2: the support or a wall when the world
        was built with ``render_static``), seen by ``camera`` (one of ``cameras``)."""
        mujoco.mj_camlight(self.model, self.data)
        images = renderer.render(self.model, self.data, camera)
        lookup = np.append(self.object_of_geom, -1).astype(np.int32)
        index = lookup[images.geom_id]
        depth = np.where(images.geom_id >= 0, images.depth_m, 0.0).astype(np.float32)
        return depth, index


# --------------------------------------------------------------------------------------------
# Building


def _mesh_asset(
    vertices: np.ndarray, faces: np.ndarray, max_hull_vertices: int = 0
) -> tuple[str, bytes]:
    """A shape's mesh as a MuJoCo binary mesh file (``.msh``: vertex, normal, texture
    coordinate and face counts as int32, then the (V, 3) vertices as float32 and the (F, 3)
    faces as int32) and its name, a digest of those bytes. Why: MuJoCo caches a mesh file's
    processing (convex hull, inertia) by its name for the process, and the stability-test
    worlds hold each neighbour's shapes again and again (each distinct shape 5-7 times in a
    pile; docs/experiments/2026-11-27-whole-run-speed-3.md); named by its content and
    compiled with the same settings everywhere (convex inertia, no scale), a shape is
    processed once. The float32 vertices are what ``uservert`` stores, so the compiled model
    is the same. ``max_hull_vertices`` (``PhysicsConfig``) enters the name: the cached
    processing includes the collision hull it bounds."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
    payload = (
        np.array([len(vertices), 0, 0, len(faces)], dtype=np.int32).tobytes()
        + vertices.tobytes()
        + faces.tobytes()
    )
    digest = hashlib.sha1(payload).hexdigest()
    suffix = f"_h{max_hull_vertices}" if max_hull_vertices else ""
    return f"ipr_convex_{digest}{suffix}.msh", payload


_CONES = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}
_SOLVERS = {
    "newton": mujoco.mjtSolver.mjSOL_NEWTON,
    "cg": mujoco.mjtSolver.mjSOL_CG,
    "pgs": mujoco.mjtSolver.mjSOL_PGS,
}


def _frame_axes(normal: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose third column is ``normal`` (unit)."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(helper, normal)
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(normal, u), normal])


def _quaternion(rotation: np.ndarray) -> list[float]:
    quaternion = np.zeros(4)
    mujoco.mju_mat2Quat(quaternion, np.asarray(rotation, float).ravel())
    return quaternion.tolist()


def support_of(planes: Sequence[KnownPlane]) -> KnownPlane | None:
    """The support among ``planes`` (None when there is none)."""
    return next((plane for plane in planes if plane.kind == "support"), None)


#: ``_wall_slab``'s recent results by (plane, thickness): every joint model of a scene is built
#: on the same planes. Holds the plane, so that its ``id`` is not reused while cached.
_SLABS: dict[tuple[int, float], tuple[KnownPlane, np.ndarray | None]] = {}
_SLABS_KEPT = 64


def _wall_slab(plane: KnownPlane, min_thickness_m: float) -> np.ndarray | None:
    """(2P, 3) vertices of a wall's slab: its points' outline on the visible face and the same
    outline ``thickness`` behind it; None when the outline is degenerate (cached per plane
    object: a plane is not changed once made)."""
    key = (id(plane), float(min_thickness_m))
    kept = _SLABS.get(key)
    if kept is not None and kept[0] is plane:
        return kept[1]
    slab = _make_wall_slab(plane, min_thickness_m)
    if len(_SLABS) >= _SLABS_KEPT:
        _SLABS.pop(next(iter(_SLABS)), None)
    _SLABS[key] = (plane, slab)
    return slab


def _make_wall_slab(plane: KnownPlane, min_thickness_m: float) -> np.ndarray | None:
    points = np.asarray(plane.points, float).reshape(-1, 3)
    if len(points) < 3:
        return None
    normal = np.asarray(plane.normal, float)
    on_face = points - np.outer(plane.signed_distance(points), normal)
    axes = _frame_axes(normal)[:, :2]
    try:
        hull = ConvexHull(on_face @ axes)
    except (QhullError, ValueError):
        return None
    outline = on_face[hull.vertices]
    thickness = max(float(plane.thickness_m), min_thickness_m)
    return np.vstack([outline, outline - thickness * normal])


def build_world(
    bodies: Sequence[Body],
    planes: Sequence[KnownPlane],
    config: PhysicsConfig | None = None,
    *,
    pusher: Pusher | None = None,
    cameras: Sequence[PinholeCamera] = (),
    render_static: bool = False,
    cached_meshes: bool = True,
) -> World:
    """Compile the MuJoCo world of ``bodies`` on ``planes`` (module doc).

    Args:
        bodies: the shapes (world frame, frame-0 poses).
        planes: the frame-0 support and walls (world frame); without a support, gravity is -z
            and nothing holds the objects up.
        config: physical parameters (default ``PhysicsConfig()``).
        pusher: the robot's pusher, parked until ``World.push``.
        cameras: cameras to render from, named ``camera_<k>`` in order.
        render_static: draw the support and walls too (index -2 in ``World.render``).
        cached_meshes: give each shape's mesh as a named asset (``_mesh_asset``), whose
            processing MuJoCo keeps in its asset cache, so that a shape already compiled in
            this process (in another world) is not processed again; False: as vertex lists
            (the same compiled model, processed every time).
    """
    config = config or PhysicsConfig()
    spec = mujoco.MjSpec()
    spec.modelname = "ipr_physics"
    spec.option.timestep = config.timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = _CONES[config.cone]
    spec.option.impratio = 10.0
    spec.option.solver = _SOLVERS[config.solver]
    spec.option.iterations = config.solver_iterations
    spec.option.tolerance = config.solver_tolerance
    spec.option.ls_iterations = config.ls_iterations
    if not config.multiccd:
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_MULTICCD
    if not config.nativeccd:
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_NATIVECCD
    support = support_of(planes)
    up = np.array([0.0, 0.0, 1.0]) if support is None else np.asarray(support.normal, float)
    spec.option.gravity = (-config.gravity_m_s2 * up).tolist()
    friction = [config.friction, config.torsional_friction, config.rolling_friction_m]
    if cameras:
        width = max(c.width for c in cameras)
        height = max(c.height for c in cameras)
        configure_visual(spec, width, height)

    world_body = spec.worldbody
    static_group = 0 if render_static else HIDDEN_GROUP
    if support is not None:
        centre = np.zeros(3)
        if bodies:
            centre = np.mean([np.mean(b.vertices, axis=0) for b in bodies], axis=0)
        centre = centre - support.signed_distance(centre[None])[0] * up
        thickness = 0.05
        world_body.add_geom(
            name="support",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[config.support_half_extent_m, config.support_half_extent_m, thickness],
            pos=(centre - thickness * up).tolist(),
            quat=_quaternion(_frame_axes(up)),
            friction=friction,
            condim=config.condim,
            group=static_group,
        )
    for number, plane in enumerate(p for p in planes if p.kind == "wall"):
        slab = _wall_slab(plane, config.wall_min_thickness_m)
        if slab is None:
            continue
        spec.add_mesh(name=f"wall_{number}", uservert=slab.ravel().tolist())
        world_body.add_geom(
            name=f"wall_{number}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"wall_{number}",
            friction=friction,
            condim=config.condim,
            group=static_group,
        )

    origins = np.zeros((len(bodies), 3))
    # A rigid group's shapes are geoms of the body made for its first shape (``Body``).
    group_body: dict[int, tuple[Any, np.ndarray, int]] = {}
    body_of_shape = list(range(len(bodies)))
    assets: dict[str, bytes] = {}
    for k, body in enumerate(bodies):
        vertices = np.asarray(body.vertices, float).reshape(-1, 3)
        faces = np.asarray(body.faces, np.int64).reshape(-1, 3)
        origin = vertices.mean(axis=0)
        origins[k] = origin
        if cached_meshes:
            asset, payload = _mesh_asset(vertices - origin, faces, config.max_hull_vertices)
            assets[asset] = payload
            mesh = spec.add_mesh(name=f"shape_{k}", file=asset)
        else:
            mesh = spec.add_mesh(
                name=f"shape_{k}",
                uservert=(vertices - origin).ravel().tolist(),
                userface=faces.astype(np.int32).ravel().tolist(),
            )
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX
        if config.max_hull_vertices:
            mesh.maxhullvert = config.max_hull_vertices
        if body.dynamic and body.rigid_group >= 0 and body.rigid_group in group_body:
            parent, group_origin, body_of_shape[k] = group_body[body.rigid_group]
            pos = (origin - group_origin).tolist()
            origins[k] = group_origin  # poses map frame 0 to now about the body's origin
        elif body.dynamic:
            parent = world_body.add_body(name=f"body_{k}", pos=origin.tolist())
            parent.add_freejoint()
            if body.switchable:
                # Gravity compensation is only computed in models compiled with some; set to 0
                # (the body falls) right after compiling, to 1 by ``World.hold``.
                parent.gravcomp = 1.0
            pos = [0.0, 0.0, 0.0]
            if body.rigid_group >= 0:
                group_body[body.rigid_group] = (parent, origin, k)
        else:
            parent, pos = world_body, origin.tolist()
        parent.add_geom(
            name=f"shape_{k}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"shape_{k}",
            pos=pos,
            density=config.density_kg_m3,
            friction=friction,
            condim=config.condim,
            contype=2 if body.candidate else 1,
            conaffinity=1,
            group=0,
        )
    if pusher is not None:
        mocap = world_body.add_body(name="pusher", mocap=True, pos=PUSHER_PARK_M.tolist())
        axis = np.asarray(pusher.axis, float)
        mocap.add_geom(
            name="pusher",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            size=[pusher.radius_m, max(pusher.length_m / 2 - pusher.radius_m, 1e-4), 0.0],
            quat=_quaternion(_frame_axes(axis)),
            friction=friction,
            condim=config.condim,
            group=HIDDEN_GROUP,
            # A higher priority: the pusher's contacts take its solref/solimp, not a mix.
            priority=1,
            solref=[config.pusher_timeconst_s, config.pusher_dampratio],
            solimp=[*config.pusher_impedance, 0.001, 0.5, 2.0],
        )
    names = []
    for number, camera in enumerate(cameras):
        names.append(f"camera_{number}")
        add_pinhole_camera(spec, camera, names[-1])

    if assets:
        spec.assets = assets
    model = spec.compile()
    model.body_gravcomp[:] = 0.0
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    body_ids = np.full(len(bodies), -1, dtype=np.int64)
    object_of_geom = np.full(model.ngeom, -1, dtype=np.int32)
    for geom in range(model.ngeom):
        if model.geom_group[geom] == 0 and model.geom(geom).name.startswith(("support", "wall_")):
            object_of_geom[geom] = -2
    for k, body in enumerate(bodies):
        if body.dynamic:
            body_ids[k] = model.body(f"body_{body_of_shape[k]}").id
        object_of_geom[model.geom(f"shape_{k}").id] = k
    pusher_geom = model.geom("pusher").id if pusher is not None else -1
    pusher_mocap = int(model.body_mocapid[model.body("pusher").id]) if pusher is not None else -1
    initial_com = np.zeros((len(bodies), 3))
    dynamic = body_ids >= 0
    initial_com[dynamic] = data.xipos[body_ids[dynamic]]
    shape_geoms = np.array([model.geom(f"shape_{k}").id for k in range(len(bodies))], np.int64)
    contacts = np.stack(
        [model.geom_contype[shape_geoms], model.geom_conaffinity[shape_geoms]], axis=1
    ).astype(np.int32)
    local_boxes = np.zeros((len(bodies), 2, 3))
    for k, body in enumerate(bodies):
        relative = np.asarray(body.vertices, float).reshape(-1, 3) - origins[k]
        local_boxes[k] = relative.min(axis=0), relative.max(axis=0)
    return World(
        model,
        data,
        tuple(bodies),
        body_ids,
        object_of_geom,
        config,
        tuple(names),
        pusher_geom,
        pusher_mocap,
        origins,
        initial_com=initial_com,
        shape_geoms=shape_geoms,
        contacts=contacts.reshape(-1, 2),
        local_boxes=local_boxes,
    )


def convex_centroid(vertices: np.ndarray) -> np.ndarray | None:
    """(3,) centre of mass (m) of the uniform solid convex hull of (V, 3) ``vertices``, as
    MuJoCo's convex mesh inertia has it; None for a flat or degenerate hull."""
    vertices = np.asarray(vertices, float).reshape(-1, 3)
    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError):
        return None
    inside = vertices[hull.vertices].mean(axis=0)
    triangles = vertices[hull.simplices]  # (F, 3, 3)
    volumes = np.abs(
        np.einsum("ij,ij->i", triangles[:, 0] - inside, np.cross(triangles[:, 1] - inside,
                                                                  triangles[:, 2] - inside))
    ) / 6.0  # fmt: skip
    total = volumes.sum()
    if total <= 0:
        return None
    centres = (triangles.sum(axis=1) + inside) / 4.0
    return (volumes[:, None] * centres).sum(axis=0) / total


def resting_drop(
    vertices: np.ndarray,
    centroid: np.ndarray,
    support: KnownPlane,
    obstacles: Sequence[np.ndarray],
    *,
    gap_m: float,
    margin_m: float,
    signed: bool = False,
) -> float | None:
    """What a stability test would measure of a convex shape that clearly rests on the support
    alone, without simulating it (None when the case is not clear: simulate it).

    Clear: its lowest vertex within ``gap_m`` of the support plane (above or below), no
    obstacle's axis-aligned box (2, 3) within ``margin_m`` of its own, and its ``centroid``
    (3,) over the outline of its vertices within 1 mm of its lowest, ``margin_m`` inside it.
    Such a shape drops by its gap onto the support and stands: its drop is the gap (0 when it
    starts sunk in). Why: most candidates are extended down to the support they nearly touch
    (``ipr_shapes.hypotheses``), and a simulation of a shape that just stands costs as much as one
    that falls. ``vertices`` (V, 3) world (m). ``signed``: the vertical motion instead
    (``World.vertical_motions``): a shape sunk in is lifted out by its depth (< 0)."""
    vertices = np.asarray(vertices, float).reshape(-1, 3)
    heights = support.signed_distance(vertices)
    lowest = float(heights.min())
    if abs(lowest) > gap_m:
        return None
    low, high = vertices.min(axis=0) - margin_m, vertices.max(axis=0) + margin_m
    for box in obstacles:
        if np.all(low <= box[1]) and np.all(box[0] <= high):
            return None
    axes = _frame_axes(np.asarray(support.normal, float))[:, :2]
    footprint = vertices[heights <= lowest + 1e-3] @ axes
    try:
        outline = ConvexHull(footprint)
    except (QhullError, ValueError):
        return None  # an edge or a point: it may tip
    inside = -float(np.max(outline.equations @ np.append(np.asarray(centroid) @ axes, 1.0)))
    if inside < margin_m:
        return None
    return lowest if signed else max(lowest, 0.0)


def wall_slabs(planes: Sequence[KnownPlane], config: PhysicsConfig) -> list[np.ndarray]:
    """(2P, 3) vertices (m, world) of each wall's convex slab as ``build_world`` makes it (walls
    with a degenerate outline left out): the static geometry a result records for exports."""
    slabs = []
    for plane in planes:
        if plane.kind != "wall":
            continue
        slab = _wall_slab(plane, config.wall_min_thickness_m)
        if slab is not None:
            slabs.append(slab)
    return slabs


def wall_boxes(planes: Sequence[KnownPlane], config: PhysicsConfig) -> list[np.ndarray]:
    """(2, 3) axis-aligned boxes (m, world) of the walls' slabs as ``build_world`` makes them."""
    return [np.stack([slab.min(axis=0), slab.max(axis=0)]) for slab in wall_slabs(planes, config)]


def decimated_camera(
    K: np.ndarray, width: int, height: int, world_from_camera: np.ndarray, factor: int
) -> PinholeCamera:
    """A camera whose pixel (u', v') sees the same ray as pixel (factor u' + factor // 2,
    factor v' + factor // 2) of the full image (``factor`` >= 1), so that rendered images
    compare with the full image sampled at those pixels (``decimated_pixels``). ``K`` (3, 3)
    intrinsics (px) and ``width`` x ``height`` (px) are the full image's; ``world_from_camera``
    (4, 4) its OpenCV camera pose (m), kept."""
    if factor < 1:
        raise ValueError(f"decimation factor must be >= 1, got {factor}")
    K = np.asarray(K, float)
    small = K.copy()
    small[0, 0] = K[0, 0] / factor
    small[1, 1] = K[1, 1] / factor
    small[0, 1] = K[0, 1] / factor
    small[0, 2] = (K[0, 2] - factor // 2) / factor
    small[1, 2] = (K[1, 2] - factor // 2) / factor
    return PinholeCamera(small, width // factor, height // factor, np.asarray(world_from_camera))


def decimated_pixels(image: np.ndarray, factor: int) -> np.ndarray:
    """Sample a full (H, W, ...) image at the pixels ``decimated_camera`` reproduces:
    (H // factor, W // factor, ...)."""
    h, w = image.shape[0] // factor, image.shape[1] // factor
    offset = factor // 2
    return image[offset : offset + h * factor : factor, offset : offset + w * factor : factor]
