"""The smooth, closed surface of a result's object shape (``ipr_shapes.export``'s visual mesh and the
body its mass and inertia come from).

A result's ``best.ply`` is one of three kinds, told apart here:

- a **voxel-face mesh** (the carved shapes of ``ipr_shapes.carving``): every vertex on the 5 mm
  lattice's corners. It is a staircase; its surface is rebuilt from its voxels. The voxels
  (``ipr_shapes.voxels``, the metric's grid) are blurred by a Gaussian of ``sigma_voxels`` and the
  blurred field is clamped so that every occupied voxel centre stays above the level 1/2 and
  every empty one below it (thin walls and one-voxel gaps survive the blur, as thin sheets
  and slits); manifold3d's marching tetrahedra (``Manifold.level_set``, in the lock already:
  no scikit-image) extracts the level 1/2 as a closed 2-manifold with edges about
  ``edge_voxels`` voxels long. The trilinear field leaves spikes a millimetre or two high
  along the lattice's lines, at corners and where the clamp acts; ``taubin_iterations`` of
  Taubin smoothing (trimesh, which barely shrinks) remove them. Blurring rounds convex edges
  inwards (2-15 % of the volume, the most on small objects), so the vertices are then moved
  along their normals by the uniform distance that restores the voxel volume (first order,
  ``volume_passes`` passes): the smooth body weighs what the voxels weigh.
- a **closed mesh** that is not on the lattice (a convex hypothesis written without carving,
  ground truth, another tool's mesh): already smooth, used as it is (re-oriented outwards).
- an **open mesh**: its convex hull, as the result contract scores it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.checks import Checks, Interval, check_fields

#: A vertex this close (m) to a lattice corner is on the lattice.
LATTICE_TOLERANCE_M = 1e-7
#: The blurred occupancy is kept at least this far from the level 1/2 at every voxel centre,
#: on the side the voxel is on.
CLAMP_MARGIN = 0.05
#: The level of the blurred occupancy is chosen in this range.
LEVEL_RANGE = (0.2, 0.8)
#: One volume pass moves the surface by at most this many voxels.
MAX_OFFSET_VOXELS = 0.25


@dataclass(frozen=True)
class SurfaceConfig:
    """How the smooth surface of a voxel-face mesh is rebuilt (module doc).

    Attributes:
        pitch_m: the voxel lattice of the result's carved meshes (the contract's 5 mm).
        sigma_voxels: standard deviation of the Gaussian blur of the occupancy, in voxels;
            0.8 removes the staircase of a 45-degree slope and keeps 5 mm detail (larger
            blurs make the clamp act more often, and its bumps with it).
        edge_voxels: target triangle edge of the extracted surface, in voxels (1: about 5 mm,
            as fine as the voxels say anything).
        taubin_iterations: Taubin smoothing passes over the extracted surface (0: none).
        volume_passes: normal-offset passes that restore the voxel volume (0: keep the
            level set's volume, a few per cent smaller on small objects); each moves the
            surface by at most a quarter voxel.
        max_volume_error: a rebuilt surface whose volume is further than this (relative) from
            the voxels' is replaced by the voxel faces themselves (parts thinner than the
            blur).
        max_voxels: refuse a shape with more voxels than this (a mesh in millimetres, say).
    """

    CHECKS: ClassVar[Checks] = {
        "pitch_m": Interval(0, None, closed="neither"),
        "sigma_voxels": Interval(0, 3),
        "edge_voxels": Interval(0.25, 4),
        "volume_passes": Interval(0, 10, integer=True),
        "max_volume_error": Interval(0, None),
        "taubin_iterations": Interval(0, 100, integer=True),
        "max_voxels": Interval(1, None, integer=True),
    }

    pitch_m: float = voxels.DEFAULT_PITCH_M
    sigma_voxels: float = 0.8
    edge_voxels: float = 1.0
    volume_passes: int = 3
    max_volume_error: float = 0.05
    taubin_iterations: int = 10
    max_voxels: int = 4_000_000

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True, eq=False)
class Surface:
    """A closed, outward-oriented surface in the world frame (metres).

    Attributes:
        mesh: the ``trimesh.Trimesh``.
        source: ``"voxels"`` (rebuilt from a voxel-face mesh), ``"voxel faces"`` (a voxel-face
            mesh kept as it is: too thin to rebuild), ``"mesh"`` (a closed mesh used as it is)
            or ``"hull"`` (the convex hull of an open mesh).
        voxel_volume_m3: volume of the shape's voxels on the lattice (the metric's volume).
        volume_error: relative difference of the surface's volume from ``voxel_volume_m3``
            (None when the shape has no voxel).
    """

    mesh: Any
    source: str
    voxel_volume_m3: float
    volume_error: float | None


def is_lattice_mesh(vertices: np.ndarray, faces: np.ndarray, pitch_m: float) -> bool:
    """True for a voxel-face mesh (``ipr_shapes.carving.voxel_surface``): every vertex on a corner of
    the ``pitch_m`` lattice and every triangle half of one voxel face (legs one pitch long).
    A box that merely has its corners on the lattice is not one."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if vertices.size == 0 or faces.size == 0:
        return False
    scaled = vertices / pitch_m
    if np.abs(scaled - np.round(scaled)).max() * pitch_m > LATTICE_TOLERANCE_M:
        return False
    corners = np.round(scaled[faces]).astype(np.int64)  # (F, 3, 3) lattice units
    squared = [
        ((corners[:, a] - corners[:, b]) ** 2).sum(axis=1) for a, b in ((0, 1), (1, 2), (2, 0))
    ]
    lengths = np.sort(np.stack(squared, axis=1), axis=1)
    return bool(np.all(lengths == [1, 1, 2]))


def smooth_surface(mesh: Any, config: SurfaceConfig | None = None) -> Surface:
    """The smooth closed surface of a result mesh (a trimesh or (vertices, faces)), world frame.

    Raises ValueError when the shape has more than ``config.max_voxels`` voxels or no volume.
    """
    import trimesh

    config = config or SurfaceConfig()
    vertices, faces = voxels._as_arrays(mesh)
    merged, merged_faces, closed = voxels.closed_or_hull(mesh)
    extent = merged.max(axis=0) - merged.min(axis=0) if len(merged) else np.zeros(3)
    estimate = float(np.prod(extent / config.pitch_m + 2))
    if estimate > 8 * config.max_voxels:
        raise ValueError(
            f"the shape is {extent.max():.3g} m across ({estimate:.3g} voxels of "
            f"{config.pitch_m * 1000:g} mm): are its coordinates in millimetres?"
        )
    keys = voxels.scanline_voxels(merged, merged_faces, config.pitch_m)
    if keys.size > config.max_voxels:
        raise ValueError(
            f"the shape holds {keys.size} voxels of {config.pitch_m * 1000:g} mm (at most "
            f"{config.max_voxels}): are its coordinates in millimetres?"
        )
    voxel_volume = voxels.volume_m3(keys, config.pitch_m)
    if closed and keys.size and is_lattice_mesh(merged, merged_faces, config.pitch_m):
        surface = voxel_level_surface(keys, config)
        source = "voxels"
        if not (
            surface.is_watertight
            and abs(surface.volume / voxel_volume - 1) <= config.max_volume_error
        ):
            # Parts thinner than the blur (a rod one voxel wide, a lone voxel) shrink to
            # threads that no offset restores: keep the voxel faces themselves.
            surface = trimesh.Trimesh(merged, merged_faces, process=True)
            source = "voxel faces"
    elif closed:
        surface = trimesh.Trimesh(merged, merged_faces, process=True)
        source = "mesh"
    else:
        surface = convex_hull(merged)
        source = "hull"
    if surface.volume < 0:
        surface.invert()
    if not surface.volume > 0:
        raise ValueError("the shape has no volume")
    error = surface.volume / voxel_volume - 1.0 if voxel_volume > 0 else None
    return Surface(surface, source, voxel_volume, error)


def convex_hull(points: np.ndarray) -> Any:
    """The convex hull of (N, 3) points as an outward-oriented trimesh (manifold3d's hull:
    trimesh's own re-orients faces through networkx, which is not installed)."""
    import manifold3d
    import trimesh

    hull = manifold3d.Manifold.hull_points(np.asarray(points, dtype=np.float64)).to_mesh()
    return trimesh.Trimesh(
        np.asarray(hull.vert_properties, dtype=np.float64)[:, :3],
        np.asarray(hull.tri_verts, dtype=np.int64),
        process=False,
    )


def occupancy_grid(keys: np.ndarray, pad: int) -> tuple[np.ndarray, np.ndarray]:
    """(nx, ny, nz) bool occupancy of voxel ``keys`` with ``pad`` empty layers around, and the
    (3,) voxel index of its cell (0, 0, 0)."""
    index = voxels.unpack(keys)
    low = index.min(axis=0) - pad
    shape = tuple(int(n) for n in index.max(axis=0) - low + pad + 1)
    occupied = np.zeros(shape, dtype=bool)
    occupied[tuple((index - low).T)] = True
    return occupied, low


def voxel_level_surface(keys: np.ndarray, config: SurfaceConfig | None = None) -> Any:
    """The smooth closed surface (trimesh, world frame) of the voxels ``keys`` (module doc)."""
    import manifold3d
    import trimesh
    from scipy.ndimage import gaussian_filter

    config = config or SurfaceConfig()
    pad = int(np.ceil(3 * config.sigma_voxels)) + 2
    occupied, low = occupancy_grid(keys, pad)
    field = occupied.astype(np.float64)
    level = 0.5
    if config.sigma_voxels > 0:
        field = gaussian_filter(field, config.sigma_voxels, mode="constant")
        level = volume_level(field, keys.size)
    # Every occupied centre inside, every empty one outside: the blur may not erase a thin
    # part or fill a narrow gap.
    field = np.where(
        occupied,
        np.maximum(field, level + CLAMP_MARGIN),
        np.minimum(field, level - CLAMP_MARGIN),
    )
    level_set = _trilinear(field - level)
    nx, ny, nz = field.shape
    manifold = manifold3d.Manifold.level_set(
        level_set, [0.0, 0.0, 0.0, nx - 1.0, ny - 1.0, nz - 1.0], config.edge_voxels
    )
    result = manifold.to_mesh()
    grid_vertices = np.asarray(result.vert_properties, dtype=np.float64)[:, :3]
    # Grid coordinate n is the centre of voxel index n + low, at (n + low + 1/2) * pitch.
    world = (grid_vertices + low + 0.5) * config.pitch_m
    surface = trimesh.Trimesh(world, np.asarray(result.tri_verts, dtype=np.int64), process=False)
    if config.taubin_iterations:
        trimesh.smoothing.filter_taubin(surface, iterations=config.taubin_iterations)
    target = voxels.volume_m3(keys, config.pitch_m)
    step = MAX_OFFSET_VOXELS * config.pitch_m
    for _ in range(config.volume_passes):
        offset = float(np.clip((target - surface.volume) / surface.area, -step, step))
        surface = trimesh.Trimesh(
            surface.vertices + surface.vertex_normals * offset, surface.faces, process=False
        )
    return surface


def volume_level(field: np.ndarray, count: int, upsample: int = 2) -> float:
    """The level of the blurred occupancy ``field`` whose inside holds ``count`` voxels'
    volume, in [0.2, 0.8] (1/2 on flat faces; lower levels give back what the blur took from
    edges and corners, where the field is flat, and barely move flat faces, where it is
    steep). Volumes are counted on the field trilinearly upsampled ``upsample`` times."""
    from scipy.ndimage import zoom

    samples = zoom(field, upsample, order=1).ravel()
    wanted = count * upsample**3  # samples above the level
    if wanted >= samples.size:
        return LEVEL_RANGE[0]
    # The order statistic of the sorted samples, without sorting them all (the same value).
    rank = samples.size - wanted - 1
    level = float(np.partition(samples, rank)[rank]) if wanted > 0 else LEVEL_RANGE[1]
    return float(np.clip(level, *LEVEL_RANGE))


def _trilinear(field: np.ndarray):
    """f(x, y, z) -> the trilinear interpolation of ``field`` (grid units), -1/2 outside.

    Plain Python over nested lists: manifold3d calls it once per grid point, and indexing
    lists is several times faster there than indexing a numpy array.
    """
    values = field.tolist()
    nx, ny, nz = field.shape

    def evaluate(x: float, y: float, z: float) -> float:
        i, j, k = int(x), int(y), int(z)
        if x < 0 or y < 0 or z < 0 or i >= nx - 1 or j >= ny - 1 or k >= nz - 1:
            return -0.5
        a, b, c = x - i, y - j, z - k
        r00, r01 = values[i][j], values[i][j + 1]
        r10, r11 = values[i + 1][j], values[i + 1][j + 1]
        return (1 - a) * (
            (1 - b) * ((1 - c) * r00[k] + c * r00[k + 1]) + b * ((1 - c) * r01[k] + c * r01[k + 1])
        ) + a * (
            (1 - b) * ((1 - c) * r10[k] + c * r10[k + 1]) + b * ((1 - c) * r11[k] + c * r11[k + 1])
        )

    return evaluate
