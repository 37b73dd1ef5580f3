"""Arrangements (table, container, drawer), the MuJoCo world of one scene, drops and pushes.

World frame: z up, gravity -z, the table top is the plane z = 0 and the arrangement is centred
at the origin. Objects are free bodies whose body frame is the object's model frame (MuJoCo shifts
the mesh geom by the mesh's own offset, so a body pose is the model pose). MuJoCo collides each
mesh as its convex hull. The pusher is a mocap body carrying the capsule; when withdrawn it is
parked far from the scene (teleported, so that withdrawing does not disturb the pile).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from ipr_shapes.synth.catalogue import ObjectModel
from ipr_shapes.synth.config import SynthConfig

#: Geom groups: rendered by default 0-2; the pusher (3) is never rendered; 4/5 isolate objects.
GROUP_OBJECTS, GROUP_TABLE, GROUP_WALLS, GROUP_PUSHER = 0, 1, 2, 3
#: Where parked objects float (gravity compensated) before they are dropped, and the pusher rests.
PARK_ORIGIN = np.array([30.0, 30.0, 10.0])
PUSHER_PARK = np.array([-30.0, -30.0, 10.0])
#: Label codes of non-object pixels in segmentation images.
LABEL_BACKGROUND, LABEL_TABLE, LABEL_FLOOR, LABEL_WALL, LABEL_FRONT_WALL = -1, -2, -3, -4, -5
TABLE_THICKNESS_M = 0.03
FLOOR_Z_M = -0.75


class Rejected(Exception):
    """A sampled configuration violates a scene rule; the generator retries with a new one."""


@dataclass(frozen=True, eq=False)
class Wall:
    """A static box: centre (3,) and half sizes (3,) in metres, world frame; RGBA colour (4,)."""

    name: str
    centre: np.ndarray
    half_size: np.ndarray
    rgba: np.ndarray
    front: bool = False


@dataclass(frozen=True, eq=False)
class Layout:
    """Static geometry of one scene.

    Attributes:
        arrangement: "table", "container" or "drawer".
        table_half_m: (2,) half extents of the table top (top face at z = 0, centred at 0).
        region_half_m: (2,) half extents of the rectangle, centred at 0, that objects must stay in
            (table top minus a margin, or the inner floor of container/drawer).
        walls: container or drawer walls (the drawer's front wall has ``front=True``, on -y).
        drop_centre_m: (2,) xy centre of the drop disc.
        table_rgb: (2, 3) two colours of the table texture in [0, 1]; floor_rgb: (2, 3) likewise.
        inner_rgba: (4,) colour of the container/drawer floor, or None.
        camera_azimuth_deg: (low, high) range of camera azimuths, or None for any.
    """

    arrangement: str
    table_half_m: np.ndarray
    region_half_m: np.ndarray
    walls: tuple[Wall, ...]
    drop_centre_m: np.ndarray
    table_rgb: np.ndarray
    floor_rgb: np.ndarray
    inner_rgba: np.ndarray | None = None
    camera_azimuth_deg: tuple[float, float] | None = None

    @property
    def wall_top_m(self) -> float:
        """Height of the highest wall (0 without walls)."""
        return max((float(w.centre[2] + w.half_size[2]) for w in self.walls), default=0.0)

    @property
    def front_wall(self) -> Wall | None:
        """The drawer's occluding front wall, or None."""
        return next((w for w in self.walls if w.front), None)


_TABLE_COLOURS = np.array(
    [
        [[0.55, 0.38, 0.22], [0.48, 0.32, 0.18]],  # wood
        [[0.80, 0.80, 0.78], [0.74, 0.74, 0.72]],  # white laminate
        [[0.42, 0.43, 0.45], [0.36, 0.37, 0.39]],  # grey
        [[0.66, 0.55, 0.40], [0.60, 0.49, 0.35]],  # light wood
    ]
)
_WALL_COLOURS = np.array(
    [
        [0.20, 0.35, 0.65],
        [0.75, 0.75, 0.72],
        [0.30, 0.30, 0.32],
        [0.62, 0.45, 0.28],
        [0.70, 0.25, 0.20],
        [0.25, 0.50, 0.35],
    ]
)


def sample_layout(
    arrangement: str, objects: list[ObjectModel], rng: np.random.Generator, config: SynthConfig
) -> Layout:
    """Random static geometry for ``arrangement``, sized for ``objects``."""
    table_half = np.array([rng.uniform(0.45, 0.6), rng.uniform(0.35, 0.45)])
    table_rgb = _TABLE_COLOURS[rng.integers(len(_TABLE_COLOURS))]
    floor_rgb = np.array([[0.30, 0.30, 0.30], [0.25, 0.25, 0.26]]) * rng.uniform(0.8, 1.2)
    if arrangement == "table":
        return Layout(
            arrangement, table_half, table_half - 0.03, (), np.zeros(2), table_rgb, floor_rgb
        )

    # Container and drawer: an open box on the table sized for the objects' footprints.
    footprints = [np.sort(item.extents)[1:] for item in objects]
    area = rng.uniform(0.75, 0.95) * sum(float(a * b) for a, b in footprints)
    largest = max(float(item.extents.max()) for item in objects)
    aspect = rng.uniform(1.1, 1.5)
    half_x = float(np.clip(max(0.5 * np.sqrt(area * aspect), 0.45 * largest + 0.02), 0.1, 0.22))
    half_y = float(np.clip(max(half_x / aspect, 0.4 * largest + 0.02), 0.09, 0.18))
    thickness = 0.01 if arrangement == "container" else 0.015
    wall_height = rng.uniform(0.07, 0.11) if arrangement == "container" else rng.uniform(0.07, 0.10)
    colour = np.append(_WALL_COLOURS[rng.integers(len(_WALL_COLOURS))], 1.0)
    # The drawer's front panel rises above its sides, between the camera and the pile.
    front_height = wall_height + (rng.uniform(0.03, 0.05) if arrangement == "drawer" else 0.0)
    walls = []
    for name, sign in (("wall_+x", 1.0), ("wall_-x", -1.0)):
        centre = np.array([sign * (half_x + thickness / 2), 0.0, wall_height / 2])
        walls.append(
            Wall(
                name, centre, np.array([thickness / 2, half_y + thickness, wall_height / 2]), colour
            )
        )
    back = np.array([0.0, half_y + thickness / 2, wall_height / 2])
    walls.append(Wall("wall_+y", back, np.array([half_x, thickness / 2, wall_height / 2]), colour))
    front = np.array([0.0, -(half_y + thickness / 2), front_height / 2])
    front_half = np.array([half_x + thickness, thickness / 2, front_height / 2])
    walls.append(Wall("wall_-y", front, front_half, colour, front=arrangement == "drawer"))
    inner = np.append(colour[:3] * rng.uniform(0.75, 0.95), 1.0)
    drop = np.zeros(2)
    azimuth = None
    if arrangement == "drawer":
        drop = np.array([0.0, -half_y + min(rng.uniform(0.04, 0.07), half_y)])  # behind the front
        spread = config.drawer_azimuth_spread_deg
        azimuth = (-90.0 - spread, -90.0 + spread)
    return Layout(
        arrangement,
        table_half,
        np.array([half_x, half_y]),
        tuple(walls),
        drop,
        table_rgb,
        floor_rgb,
        inner,
        azimuth,
    )


# --------------------------------------------------------------------------------------------
# The MuJoCo world


def _mjcf_base(layout: Layout, config: SynthConfig, light_dir: np.ndarray) -> str:
    (t1, t2), (f1, f2) = layout.table_rgb, layout.floor_rgb
    table = layout.table_half_m

    def rgb(value: np.ndarray) -> str:
        return " ".join(f"{x:.4f}" for x in value)

    walls = "".join(
        f'<geom name="{w.name}" type="box" pos="{rgb(w.centre)}" size="{rgb(w.half_size)}" '
        f'rgba="{rgb(w.rgba)}" material="wall" group="{GROUP_WALLS}"/>'
        for w in layout.walls
    )
    if layout.inner_rgba is not None:  # visual floor of the box, 0.5 mm above the table
        half = layout.region_half_m
        walls += (
            f'<geom name="inner_floor" type="box" pos="0 0 0.00025" '
            f'size="{half[0]:.4f} {half[1]:.4f} 0.00025" rgba="{rgb(layout.inner_rgba)}" '
            f'material="wall" contype="0" conaffinity="0" group="{GROUP_WALLS}"/>'
        )
    light_pos = -light_dir * 2.0
    pusher_half = config.pusher_length_m / 2 - config.pusher_radius_m
    return f"""<mujoco model="ipr_synth">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{config.timestep_s}" integrator="implicitfast" cone="elliptic" impratio="10">
    <flag multiccd="enable"/>
  </option>
  <statistic extent="1" center="0 0 0"/>
  <visual>
    <global offwidth="{config.width}" offheight="{config.height}"/>
    <map znear="0.05" zfar="12"/>
    <quality shadowsize="2048" offsamples="4"/>
    <headlight ambient="0.32 0.32 0.32" diffuse="0.30 0.30 0.30" specular="0.05 0.05 0.05"/>
  </visual>
  <default>
    <geom friction="{config.support_friction} {config.torsional_friction} \
{config.rolling_friction_m}" condim="6"/>
  </default>
  <asset>
    <texture name="table" type="cube" builtin="flat" rgb1="{rgb(t1)}" rgb2="{rgb(t2)}"
             mark="random" markrgb="{rgb(t2 * 0.9)}" random="0.3" width="512" height="512"/>
    <material name="table" texture="table" specular="0.1" shininess="0.2"/>
    <texture name="floor" type="2d" builtin="checker" rgb1="{rgb(f1)}" rgb2="{rgb(f2)}"
             width="256" height="256"/>
    <material name="floor" texture="floor" texrepeat="6 6" specular="0.05"/>
    <material name="wall" specular="0.15" shininess="0.3"/>
    <material name="object" specular="0.15" shininess="0.25" rgba="1 1 1 1"/>
  </asset>
  <worldbody>
    <light name="key" pos="{rgb(light_pos)}" dir="{rgb(light_dir)}" directional="true"
           castshadow="true" diffuse="0.55 0.55 0.55" specular="0.1 0.1 0.1"/>
    <geom name="floor" type="plane" pos="0 0 {FLOOR_Z_M}" size="3 3 0.1" material="floor"
          group="{GROUP_TABLE}"/>
    <geom name="table" type="box" pos="0 0 {-TABLE_THICKNESS_M / 2}"
          size="{table[0]:.4f} {table[1]:.4f} {TABLE_THICKNESS_M / 2}" material="table"
          group="{GROUP_TABLE}"/>
    {walls}
    <body name="pusher" mocap="true" pos="{rgb(PUSHER_PARK)}">
      <geom name="pusher" type="capsule" size="{config.pusher_radius_m} {pusher_half}"
            rgba="0.9 0.9 0.9 1" group="{GROUP_PUSHER}" solref="0.004 1"
            solimp="0.95 0.99 0.001" solmix="1000"/>
    </body>
    <camera name="camera" pos="0 -1 1" xyaxes="1 0 0 0 0.7 0.7"/>
  </worldbody>
</mujoco>"""


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random (3, 3) rotation matrix."""
    return Rotation.random(random_state=rng).as_matrix()


@dataclass(eq=False)
class PileWorld:
    """MuJoCo model and state of one scene configuration.

    ``objects[i]`` is body ``obj_i`` with geom ``geom_ids[i]``; ``frictions[i]`` its sliding
    friction; ``light_dir`` (3,) the unit direction of the key light (shadows).
    """

    layout: Layout
    objects: list[ObjectModel]
    frictions: np.ndarray
    config: SynthConfig
    light_dir: np.ndarray
    model: mujoco.MjModel = field(init=False)
    data: mujoco.MjData = field(init=False)

    def __post_init__(self) -> None:
        spec = mujoco.MjSpec.from_string(_mjcf_base(self.layout, self.config, self.light_dir))
        for index, item in enumerate(self.objects):
            spec.add_mesh(
                name=f"mesh_{index}",
                uservert=item.vertices.ravel().tolist(),
                userface=item.faces.ravel().tolist(),
            )
            # Parked objects float (gravity compensated) until dropped; gravcomp must be set
            # before compiling for MuJoCo to evaluate it at all.
            body = spec.worldbody.add_body(name=f"obj_{index}", pos=self._park(index), gravcomp=1.0)
            body.add_freejoint()
            body.add_geom(
                name=f"obj_{index}",
                type=mujoco.mjtGeom.mjGEOM_MESH,
                meshname=f"mesh_{index}",
                mass=item.mass_kg,
                material="object",
                rgba=[1.0, 1.0, 1.0, 1.0],
                condim=6,
                friction=[
                    float(self.frictions[index]),
                    self.config.torsional_friction,
                    self.config.rolling_friction_m,
                ],
                group=GROUP_OBJECTS,
            )
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        model = self.model
        self.body_ids = np.array([model.body(f"obj_{i}").id for i in range(len(self.objects))])
        self.geom_ids = np.array([model.geom(f"obj_{i}").id for i in range(len(self.objects))])
        self.qpos_adr = np.array([model.jnt_qposadr[model.body_jntadr[b]] for b in self.body_ids])
        self.qvel_adr = np.array([model.jnt_dofadr[model.body_jntadr[b]] for b in self.body_ids])
        self.pusher_geom = model.geom("pusher").id
        self.pusher_mocap = model.body_mocapid[model.body("pusher").id]
        self.wall_geoms = np.array([model.geom(w.name).id for w in self.layout.walls], dtype=int)
        self.labels = self._label_table()
        self.hulls = [item.hull_vertices for item in self.objects]
        self.dropped = np.zeros(len(self.objects), dtype=bool)
        mujoco.mj_forward(self.model, self.data)

    def _park(self, index: int) -> list[float]:
        return (PARK_ORIGIN + [1.0 * index, 0.0, 0.0]).tolist()

    def _label_table(self) -> np.ndarray:
        """Segmentation label per geom id: object index, or a negative LABEL_* code."""
        model = self.model
        labels = np.full(model.ngeom, LABEL_BACKGROUND, dtype=np.int32)
        labels[model.geom("table").id] = LABEL_TABLE
        labels[model.geom("floor").id] = LABEL_FLOOR
        for wall, geom in zip(self.layout.walls, self.wall_geoms, strict=True):
            labels[geom] = LABEL_FRONT_WALL if wall.front else LABEL_WALL
        if self.layout.inner_rgba is not None:
            labels[model.geom("inner_floor").id] = LABEL_TABLE
        labels[self.geom_ids] = np.arange(len(self.objects))
        return labels

    # ----------------------------------------------------------------------------------------
    # State

    def poses(self, data: mujoco.MjData | None = None) -> np.ndarray:
        """(n, 4, 4) world-from-model transforms of the objects (body frames), metres."""
        data = data or self.data
        result = np.tile(np.eye(4), (len(self.objects), 1, 1))
        result[:, :3, :3] = data.xmat[self.body_ids].reshape(-1, 3, 3)
        result[:, :3, 3] = data.xpos[self.body_ids]
        return result

    def hull_world(self, index: int, poses: np.ndarray | None = None) -> np.ndarray:
        """(K, 3) convex-hull vertices of object ``index`` in the world frame."""
        pose = (self.poses() if poses is None else poses)[index]
        return self.hulls[index] @ pose[:3, :3].T + pose[:3, 3]

    def save(self) -> np.ndarray:
        """Full integration state (for deterministic retries)."""
        state = np.empty(mujoco.mj_stateSize(self.model, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(self.model, self.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        return state

    def restore(self, state: np.ndarray) -> None:
        """Return to a state from ``save``."""
        mujoco.mj_setState(self.model, self.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(self.model, self.data)

    # ----------------------------------------------------------------------------------------
    # Simulation

    def settle(self, max_s: float, *, indices: np.ndarray | None = None) -> bool:
        """Step until every dropped object is slower than the settle thresholds (True) or
        ``max_s`` of simulated time passed (False). Raises Rejected when an object falls."""
        config = self.config
        active = np.flatnonzero(self.dropped) if indices is None else indices
        check_every = max(1, int(round(0.05 / config.timestep_s)))
        steps = int(np.ceil(max_s / config.timestep_s))
        calm = 0
        for step in range(1, steps + 1):
            mujoco.mj_step(self.model, self.data)
            if step % check_every:
                continue
            velocities = self.data.qvel[self.qvel_adr[active, None] + np.arange(6)]
            if np.any(self.data.xipos[self.body_ids[active], 2] < -0.02):  # centres of mass
                raise Rejected("an object fell off the table")
            linear = np.linalg.norm(velocities[:, :3], axis=1)
            angular = np.linalg.norm(velocities[:, 3:], axis=1)
            slow = (
                linear.max() < config.settle_linear_m_s
                and angular.max() < config.settle_angular_rad_s
            )
            calm = calm + 1 if slow else 0
            if calm >= 2:  # slow at two checks in a row, not just at the turn of a rocking motion
                return True
        return False

    def set_drop_damping(self, enabled: bool) -> None:
        """Damp the objects' velocities (time constant ``drop_damping_s``) while they are being
        dropped, so that the pile forms like objects set down rather than thrown; the final
        settle runs without damping, so the pile is stable under the true dynamics."""
        rate = 1.0 / self.config.drop_damping_s if enabled else 0.0
        for index, body in enumerate(self.body_ids):
            adr = self.qvel_adr[index]
            self.model.dof_damping[adr : adr + 3] = rate * self.model.body_mass[body]
            self.model.dof_damping[adr + 3 : adr + 6] = rate * self.model.body_inertia[body]

    def drop_all(self, rng: np.random.Generator) -> None:
        """Drop the objects one by one, randomly oriented, above the drop disc; settle the pile.

        Raises Rejected when the pile does not settle or breaks a rule (``check``).
        """
        config, layout = self.config, self.layout
        self.set_drop_damping(True)
        for index, item in enumerate(self.objects):
            rotation = random_rotation(rng)
            angle, radius = rng.uniform(0, 2 * np.pi), config.drop_radius_m * np.sqrt(rng.uniform())
            xy = layout.drop_centre_m + radius * np.array([np.cos(angle), np.sin(angle)])
            if layout.walls:  # fall straight into the box: keep the bounding sphere off the walls
                limit = np.maximum(layout.region_half_m - 0.8 * item.radius, 0.0)
                xy = np.clip(xy, -limit, limit)
            top = self.local_top(xy, item.radius)
            centre = np.array([xy[0], xy[1], top + item.radius + config.drop_gap_m])
            adr = self.qpos_adr[index]
            self.data.qpos[adr : adr + 3] = centre - rotation @ item.centre
            x, y, z, w = Rotation.from_matrix(rotation).as_quat()
            self.data.qpos[adr + 3 : adr + 7] = [w, x, y, z]
            self.data.qvel[self.qvel_adr[index] : self.qvel_adr[index] + 6] = 0.0
            self.model.body_gravcomp[self.body_ids[index]] = 0.0
            self.dropped[index] = True
            mujoco.mj_forward(self.model, self.data)
            self.settle(config.drop_settle_max_s)
        self.set_drop_damping(False)
        if not self.settle(config.settle_max_s):
            raise Rejected("the pile did not settle")
        self.check(require_pile=True)

    def local_top(self, xy: np.ndarray, radius: float) -> float:
        """Highest z (m) of dropped objects and walls within ``radius`` of ``xy`` (0 if none):
        a sphere of that radius centred above it, plus a gap, touches nothing."""
        top = 0.0
        poses = self.poses()
        for index in np.flatnonzero(self.dropped):
            hull = self.hull_world(index, poses)
            near = np.linalg.norm(hull[:, :2] - xy, axis=1) < radius
            if near.any():
                top = max(top, float(hull[near, 2].max()))
        for wall in self.layout.walls:
            gap = np.maximum(np.abs(xy - wall.centre[:2]) - wall.half_size[:2], 0.0)
            if np.linalg.norm(gap) < radius:
                top = max(top, float(wall.centre[2] + wall.half_size[2]))
        return top

    def pile_top(self) -> float:
        """Highest z (m) of the dropped objects' hulls (0 when none)."""
        poses = self.poses()
        tops = [self.hull_world(i, poses)[:, 2].max() for i in np.flatnonzero(self.dropped)]
        return float(max(tops, default=0.0))

    def pile_bounds(self) -> np.ndarray:
        """(2, 3) min and max corners of the objects' world bounding box, metres."""
        poses = self.poses()
        points = np.concatenate([self.hull_world(i, poses) for i in range(len(self.objects))])
        return np.stack([points.min(axis=0), points.max(axis=0)])

    def check(self, *, require_pile: bool) -> None:
        """Raise Rejected if an object left its region, contacts penetrate too deeply, or (with
        ``require_pile``) the objects do not form one touching pile."""
        layout, config = self.layout, self.config
        poses = self.poses()
        tolerance = 0.05 if layout.walls else 0.0  # leaning over a rim is fine
        for index in range(len(self.objects)):
            hull = self.hull_world(index, poses)
            centre = self.data.xipos[self.body_ids[index]]
            if np.any(np.abs(centre[:2]) > layout.region_half_m):
                raise Rejected(f"object {self.objects[index].name} left the {layout.arrangement}")
            if np.any(np.abs(hull[:, :2]) > layout.region_half_m + tolerance):
                raise Rejected(
                    f"object {self.objects[index].name} hangs outside the {layout.arrangement}"
                )
            if hull[:, 2].min() < -config.max_penetration_m:
                raise Rejected(f"object {self.objects[index].name} sank into the table")
        count = self.data.ncon
        if count:
            depth = -float(self.data.contact.dist[:count].min())
            if depth > config.max_penetration_m:
                raise Rejected(f"contacts penetrate {depth * 1000:.1f} mm")
        if require_pile:
            needed = min(
                len(self.objects),
                max(3, int(np.ceil(config.min_pile_fraction * len(self.objects)))),
            )
            if self.largest_pile() < needed:
                raise Rejected(f"fewer than {needed} objects touch each other in one pile")

    def largest_pile(self, gap_m: float = 0.005) -> int:
        """Number of objects in the largest group whose members touch (hull distance below
        ``gap_m``); in a container or drawer, touching the walls also connects (the box holds
        the objects together)."""
        count = len(self.objects)
        parent = list(range(count + 1))  # node ``count`` stands for all walls

        def find(i: int) -> int:
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i

        model, data = self.model, self.data
        others = [(j, int(g)) for j, g in enumerate(self.geom_ids)]
        others += [(count, int(g)) for g in self.wall_geoms]
        for i, geom in enumerate(self.geom_ids):
            for j, other in others:
                if (j <= i and j != count) or find(i) == find(j):
                    continue
                if mujoco.mj_geomDistance(model, data, int(geom), other, gap_m, None) < gap_m:
                    parent[find(i)] = find(j)
        roots = [find(i) for i in range(count)]  # the wall node itself is not counted
        return max(roots.count(root) for root in set(roots))

    # ----------------------------------------------------------------------------------------
    # Pushes

    @property
    def pusher_centre_z(self) -> float:
        """Height of the capsule centre when its bottom tip is ``pusher_lift_m`` above z = 0."""
        return self.config.pusher_lift_m + self.config.pusher_length_m / 2

    def make_probe(self) -> mujoco.MjData:
        """A scratch MjData holding the current object poses, for ``pusher_clearance``."""
        probe = mujoco.MjData(self.model)
        probe.qpos[:] = self.data.qpos
        return probe

    def pusher_clearance(self, centre: np.ndarray, probe: mujoco.MjData) -> float:
        """Smallest signed distance (m) from the capsule at ``centre`` to any object hull, with
        the objects posed as in ``probe`` (from ``make_probe``)."""
        probe.mocap_pos[self.pusher_mocap] = centre
        mujoco.mj_kinematics(self.model, probe)
        return min(
            mujoco.mj_geomDistance(self.model, probe, self.pusher_geom, int(geom), 0.1, None)
            for geom in self.geom_ids
        )

    def push_region_half(self) -> np.ndarray:
        """(2,) half extents of the rectangle the capsule centre may sweep."""
        margin = self.config.pusher_radius_m + self.config.push_clearance_m
        return self.layout.region_half_m - margin

    def run_push(
        self, start: np.ndarray, direction: np.ndarray, distance: float, speed: float
    ) -> tuple[float, bool]:
        """Move the capsule centre from ``start`` along ``direction`` for up to ``distance`` at
        ``speed``, withdraw it (teleported away) and let the objects settle.

        Like a force-limited robot, the capsule stops early when it sinks more than
        ``push_stop_intrusion_m`` into an object (the object is jammed against a wall or
        other objects). Returns the distance actually travelled (m) and whether the objects
        settled. Raises Rejected when an object falls off the table.
        """
        config = self.config
        self.data.mocap_pos[self.pusher_mocap] = start
        steps = int(np.ceil(distance / speed / config.timestep_s))
        travelled = 0.0
        for step in range(1, steps + 1):
            travelled = min(step * config.timestep_s * speed, distance)
            self.data.mocap_pos[self.pusher_mocap] = start + direction * travelled
            mujoco.mj_step(self.model, self.data)
            count = self.data.ncon
            if count:
                touching = (self.data.contact.geom[:count] == self.pusher_geom).any(axis=1)
                if touching.any():
                    depth = -float(self.data.contact.dist[:count][touching].min())
                    if depth > config.push_stop_intrusion_m:
                        break
        self.data.mocap_pos[self.pusher_mocap] = PUSHER_PARK
        return travelled, self.settle(config.settle_max_s)
