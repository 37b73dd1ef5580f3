"""Rigid bodies of a result's objects: surface in an object frame, pose, mass, inertia and
convex collision pieces (the support and the start poses: ``ipr_shapes.export.placement``).

- **Object frame**: origin at the centre of mass (below), axes parallel to the world's (z up);
  the smooth surface (``ipr_shapes.export.surface``) and the pieces are given in it. Settling
  (``ipr_shapes.export.placement``) turns the meshes in this frame rather than the frame. The pose (world from object) is
  then the centre of mass's position: the result knows where an object is, not which way its
  "front" faces, and a frame from principal axes would flip or spin with a tiny change of shape
  (two or three equal moments for a cylinder or a cube). The principal axes are written where
  they belong, as the inertial frame of every format (diagonal inertia, rotated), so tools that
  read only ixx, iyy, izz are right too.
- **Mass and inertia**: the collision pieces' filled at ``density_kg_m3`` (default
  ``PhysicsConfig.density_kg_m3``, 400 kg/m^3, the inference's own), so the body that carries
  the mass is the body that touches: with ``"hull"`` that is the convex body the inference
  simulated. A carved shape's own centre of mass lies behind its hull's (the carving removed
  voxels in front), and a hull tilted or rolled around a contact line that was not under it
  (docs/experiments/2026-11-26-export-rest.md).
- **Collision**: ``"hull"`` (default), the surface's convex hull, one piece: a carved shape is
  its convex hypothesis less some voxels in front of the observed surface, so the hull adds
  5-20 % of the volume on the generated scenes, about the convex hypothesis the inference
  simulated; ``"coacd"``, CoACD's approximate convex
  decomposition (the optional ``coacd`` package), for shapes that are far from convex (ground
  truth, say), at 2-120 s per object on this machine.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ipr_shapes.checks import Checks, Interval, Options, OrNone, check_fields
from ipr_shapes.export.surface import SurfaceConfig, convex_hull, smooth_surface
from ipr_shapes.physics import PhysicsConfig

#: Collision geometries: one convex hull, or CoACD's decomposition.
COLLISION_METHODS = ("hull", "coacd")


@dataclass(frozen=True)
class ExportConfig:
    """Settings of ``ipr_shapes.export`` (module doc).

    Attributes:
        density_kg_m3: uniform density of every object (kg/m^3).
        collision: ``"hull"`` or ``"coacd"`` (``COLLISION_METHODS``).
        coacd_threshold: CoACD's concavity threshold (its default, 0.05).
        coacd_max_pieces: at most this many pieces per object from CoACD.
        support_z_m: height of the support plane (m, world frame); None: chosen (module doc).
        support_search_m: the support is z = 0 when the lowest object point is this close to it.
        separation_tolerance_m: start poses are separated until no contact is deeper than this.
        separation_iterations: at most this many separation rounds.
        settle: let the separated scene settle in MuJoCo and export the poses it came to rest
            in (``ipr_shapes.export.placement``); False: export the separated poses.
        settle_max_s: longest settling (s, simulated).
        settle_window_s: the scene is at rest when over the last this many seconds...
        settle_distance_m: ...every object's centre of mass moved less than this (m)...
        settle_angle_deg: ...and it turned less than this (degrees). Poses, not speeds:
            resting mesh contacts keep a jitter of a few mm/s that goes nowhere.
        friction: sliding, torsional and rolling friction of every geom (the inference's).
        timestep_s: the MJCF's simulation step (the inference's).
        surface: how voxel shapes become smooth surfaces.
    """

    CHECKS: ClassVar[Checks] = {
        "density_kg_m3": Interval(0, None, closed="neither"),
        "collision": Options(*COLLISION_METHODS),
        "coacd_threshold": Interval(0.01, 1),
        "coacd_max_pieces": Interval(1, 256, integer=True),
        "support_z_m": OrNone(Interval()),
        "support_search_m": Interval(0, None),
        "separation_tolerance_m": Interval(0, None, closed="neither"),
        "separation_iterations": Interval(0, None, integer=True),
        "settle_max_s": Interval(0, 60, closed="right"),
        "settle_window_s": Interval(0.01, 10),
        "settle_distance_m": Interval(0, None, closed="neither"),
        "settle_angle_deg": Interval(0, 180, closed="right"),
        "timestep_s": Interval(0, None, closed="neither"),
    }

    density_kg_m3: float = PhysicsConfig.density_kg_m3
    collision: str = "hull"
    coacd_threshold: float = 0.05
    coacd_max_pieces: int = 8
    support_z_m: float | None = None
    support_search_m: float = 0.02
    separation_tolerance_m: float = 1e-4
    separation_iterations: int = 200
    settle: bool = True
    settle_max_s: float = 30.0
    settle_window_s: float = 1.0
    settle_distance_m: float = 0.003
    settle_angle_deg: float = 3.0
    friction: tuple[float, float, float] = (
        PhysicsConfig.friction,
        PhysicsConfig.torsional_friction,
        PhysicsConfig.rolling_friction_m,
    )
    timestep_s: float = PhysicsConfig.timestep_s
    surface: SurfaceConfig = field(default_factory=SurfaceConfig)

    def __post_init__(self) -> None:
        check_fields(self)


class CollisionUnavailable(RuntimeError):
    """The chosen collision method needs a package that is not installed."""


@dataclass(frozen=True, eq=False)
class ObjectBody:
    """One object as a rigid body.

    Attributes:
        id: the object's id in the result.
        name: ``object_<id>``, the name of its body, link, model and files.
        probability: the result's probability of its shape.
        surface: ``trimesh.Trimesh``, closed, object frame (m).
        collision: convex ``trimesh.Trimesh`` pieces, object frame (m).
        position_m: (3,) world position of the object frame's origin (its centre of mass), after
            separation and settling; the object frame's axes are the world's.
        mass_kg: mass at the configured density.
        inertia_kg_m2: (3, 3) inertia tensor about the centre of mass, object-frame axes.
        principal_moments_kg_m2: (3,) ascending eigenvalues of ``inertia_kg_m2``.
        principal_axes: (3, 3) rotation whose columns are the principal axes (object frame).
        surface_source: ``"voxels"``, ``"mesh"`` or ``"hull"`` (``ipr_shapes.export.surface``).
        voxel_volume_m3: the result shape's volume on the 5 mm lattice.
        volume_error: the surface's volume relative to ``voxel_volume_m3``, minus 1.
        displacement_m: (3,) how far separation and settling moved its centre of mass from
            the result's pose (m).
        timing_s: seconds spent on its ``surface`` and ``collision``.
        rotation_deg: how far settling turned it (degrees; the meshes and the inertia in the
            object frame are turned, ``ipr_shapes.export.placement``).
    """

    id: int
    name: str
    probability: float
    surface: Any
    collision: tuple[Any, ...]
    position_m: np.ndarray
    mass_kg: float
    inertia_kg_m2: np.ndarray
    principal_moments_kg_m2: np.ndarray
    principal_axes: np.ndarray
    surface_source: str
    voxel_volume_m3: float
    volume_error: float | None
    displacement_m: np.ndarray
    timing_s: dict[str, float]
    rotation_deg: float = 0.0

    @property
    def world_from_object(self) -> np.ndarray:
        """(4, 4) pose: identity rotation, translation ``position_m``."""
        pose = np.eye(4)
        pose[:3, 3] = self.position_m
        return pose

    @property
    def volume_m3(self) -> float:
        return float(self.surface.volume)


def object_body(
    object_id: int, mesh: Any, probability: float, config: ExportConfig | None = None
) -> ObjectBody:
    """The rigid body of one result object's mesh (a trimesh or (vertices, faces), world frame).

    Raises ValueError for a shape with no volume or absurd size, CollisionUnavailable when
    CoACD is asked for and missing.
    """
    config = config or ExportConfig()
    started = time.perf_counter()
    surface = smooth_surface(mesh, config.surface)
    surface_s = time.perf_counter() - started
    world = surface.mesh
    # The pieces are computed around the surface's own centre (CoACD is not translation
    # invariant in floating point), then everything moves to the pieces' centre of mass.
    surface_centre = np.asarray(world.center_mass, dtype=np.float64)
    local = world.copy()
    local.apply_translation(-surface_centre)
    started = time.perf_counter()
    pieces = collision_pieces(local, config)
    collision_s = time.perf_counter() - started
    mass, offset, inertia = solid_properties(pieces, config.density_kg_m3)
    local.apply_translation(-offset)
    for piece in pieces:
        piece.apply_translation(-offset)
    moments, axes = principal_frame(inertia)
    return ObjectBody(
        id=int(object_id),
        name=f"object_{object_id}",
        probability=float(probability),
        surface=local,
        collision=tuple(pieces),
        position_m=surface_centre + offset,
        mass_kg=mass,
        inertia_kg_m2=inertia,
        principal_moments_kg_m2=moments,
        principal_axes=axes,
        surface_source=surface.source,
        voxel_volume_m3=surface.voxel_volume_m3,
        volume_error=surface.volume_error,
        displacement_m=np.zeros(3),
        timing_s={"surface": surface_s, "collision": collision_s},
    )


def solid_properties(
    pieces: Sequence[Any], density_kg_m3: float
) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), centre of mass (3,) and inertia tensor (3, 3) about it (kg m^2, the pieces'
    axes) of the closed ``pieces`` filled at ``density_kg_m3``: the body a simulator collides
    is the body that carries the mass (module doc)."""
    import trimesh

    solid = trimesh.util.concatenate(list(pieces))
    solid.density = density_kg_m3
    centre = np.asarray(solid.center_mass, dtype=np.float64)
    solid.apply_translation(-centre)
    inertia = np.asarray(solid.moment_inertia, dtype=np.float64)
    return float(solid.mass), centre, (inertia + inertia.T) / 2


def principal_frame(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ascending principal moments (3,) and the rotation (3, 3, columns the axes, det +1)."""
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, axes


def collision_pieces(surface: Any, config: ExportConfig) -> list[Any]:
    """Convex pieces (trimesh, the surface's frame) covering the closed ``surface``."""
    if config.collision == "hull":
        return [convex_hull(surface.vertices)]
    return _coacd_pieces(surface, config)


def require_collision_method(config: ExportConfig) -> None:
    """Raise CollisionUnavailable when ``config.collision`` needs a package that is missing."""
    if config.collision == "coacd":
        try:
            import coacd  # noqa: F401
        except ImportError:
            raise CollisionUnavailable(
                "collision 'coacd' needs the coacd package (pip install coacd); or use 'hull'"
            ) from None


def _coacd_pieces(surface: Any, config: ExportConfig) -> list[Any]:
    require_collision_method(config)
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(surface.vertices), np.asarray(surface.faces)),
        threshold=config.coacd_threshold,
        max_convex_hull=config.coacd_max_pieces,
        preprocess_mode="auto",
        seed=0,
    )
    pieces = [convex_hull(vertices) for vertices, _ in parts if len(vertices) >= 4]
    pieces = [piece for piece in pieces if len(piece.faces) and piece.volume > 0]
    return pieces or [convex_hull(surface.vertices)]
