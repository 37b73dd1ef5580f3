"""Rigid bodies of a result's objects: surface in an object frame, pose, mass, inertia and
convex collision pieces (the support and the start poses: ``ipr_shapes.export.placement``).

- **Object frame**: origin at the centre of mass of the smooth surface (``ipr_shapes.export.surface``)
  of uniform density, axes parallel to the world's (z up). The pose (world from object) is
  then the centre of mass's position: the result knows where an object is, not which way its
  "front" faces, and a frame from principal axes would flip or spin with a tiny change of shape
  (two or three equal moments for a cylinder or a cube). The principal axes are written where
  they belong, as the inertial frame of every format (diagonal inertia, rotated), so tools that
  read only ixx, iyy, izz are right too.
- **Mass and inertia**: the surface's, at ``density_kg_m3`` (default
  ``PhysicsConfig.density_kg_m3``, 400 kg/m^3, the inference's own).
- **Collision**: ``"hull"`` (default), the surface's convex hull, one piece: a carved shape is
  its convex hypothesis less some voxels in front of the observed surface, so the hull adds
  little (1-5 % of the volume on the generated scenes) and lies within the hypothesis the
  inference kept clear of the other objects; ``"coacd"``, CoACD's approximate convex
  decomposition (the optional ``coacd`` package), for shapes that are far from convex (ground
  truth, say), at 2-120 s per object on this machine.
"""

from __future__ import annotations

import time
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
            separation; the object frame's axes are the world's.
        mass_kg: mass at the configured density.
        inertia_kg_m2: (3, 3) inertia tensor about the centre of mass, object-frame axes.
        principal_moments_kg_m2: (3,) ascending eigenvalues of ``inertia_kg_m2``.
        principal_axes: (3, 3) rotation whose columns are the principal axes (object frame).
        surface_source: ``"voxels"``, ``"mesh"`` or ``"hull"`` (``ipr_shapes.export.surface``).
        voxel_volume_m3: the result shape's volume on the 5 mm lattice.
        volume_error: the surface's volume relative to ``voxel_volume_m3``, minus 1.
        displacement_m: (3,) how far separation moved it from the result's pose.
        timing_s: seconds spent on its ``surface`` and ``collision``.
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
    world.density = config.density_kg_m3
    centre = np.asarray(world.center_mass, dtype=np.float64)
    local = world.copy()
    local.apply_translation(-centre)
    local.density = config.density_kg_m3
    inertia = np.asarray(local.moment_inertia, dtype=np.float64)
    inertia = (inertia + inertia.T) / 2
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    started = time.perf_counter()
    pieces = collision_pieces(local, config)
    collision_s = time.perf_counter() - started
    return ObjectBody(
        id=int(object_id),
        name=f"object_{object_id}",
        probability=float(probability),
        surface=local,
        collision=tuple(pieces),
        position_m=centre,
        mass_kg=float(local.mass),
        inertia_kg_m2=inertia,
        principal_moments_kg_m2=moments,
        principal_axes=axes,
        surface_source=surface.source,
        voxel_volume_m3=surface.voxel_volume_m3,
        volume_error=surface.volume_error,
        displacement_m=np.zeros(3),
        timing_s={"surface": surface_s, "collision": collision_s},
    )


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
