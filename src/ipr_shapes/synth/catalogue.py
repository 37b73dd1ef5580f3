"""Object sources of the scene generator: the YCB pool and procedural shapes; BOP model export.

YCB pool rule (MuJoCo collides every mesh as its convex hull, so objects whose hull differs much
from their shape would float or hook in ways the ground-truth mesh does not show):

* solidity = mesh volume / convex-hull volume >= ``min_solidity`` (0.75): drops bowls, mugs,
  cups, clamps, tools, the skillet lid, the chain, the banana;
* smallest extent >= ``min_extent_m`` (1.5 cm): drops cutlery and other thin objects;
* largest extent <= ``max_extent_m`` (26 cm);
* catalogue mass / mesh volume within ``density_range_kg_m3`` (50-3000 kg/m^3): drops entries
  whose catalogue mass belongs to a different item than the mesh (marbles, wood blocks).

With the shared data this keeps 24 of the 63 objects (cans, boxes, bottles, fruit, balls, the
wood block, the foam brick, the peg test board, the marker, the pitcher).

Object ids: a YCB object's BOP id is its 1-based index in the sorted list of all ``.ply`` files of
the YCB models folder (stable across pools); procedural shapes have ids from
``PROCEDURAL_FIRST_ID`` so that the two sources never share an id in one models folder.
"""

from __future__ import annotations

import functools
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from ipr_shapes.synth.config import SynthConfig

PROCEDURAL_FIRST_ID = 1001
PROCEDURAL_COUNT = 24
#: Seed of the fixed procedural catalogue (the shapes are the same in every scene and run).
PROCEDURAL_SEED = 20180101


@dataclass(frozen=True, eq=False)
class ObjectModel:
    """A rigid object: mesh in its model frame (metres), colours and mass.

    Attributes:
        obj_id: BOP object id.
        name: readable name (``002_master_chef_can``, ``box_03``).
        vertices: (N, 3) float64, metres, model frame.
        faces: (F, 3) int32 vertex indices, counter-clockwise seen from outside.
        colors: (N, 3) uint8 per-vertex RGB.
        mass_kg: mass used by the simulation.
        hull_volume_m3: volume of the convex hull (what MuJoCo collides), m^3.
        volume_m3: volume of the closed mesh, m^3.
        source: "ycb" or "procedural".
    """

    obj_id: int
    name: str
    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    mass_kg: float
    hull_volume_m3: float
    volume_m3: float
    source: str

    @functools.cached_property
    def extents(self) -> np.ndarray:
        """(3,) axis-aligned bounding-box size in the model frame, metres."""
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)

    @functools.cached_property
    def centre(self) -> np.ndarray:
        """(3,) centre of the model-frame bounding box, metres."""
        return (self.vertices.max(axis=0) + self.vertices.min(axis=0)) / 2.0

    @functools.cached_property
    def radius(self) -> float:
        """Radius of the bounding sphere about ``centre``, metres."""
        return float(np.linalg.norm(self.vertices - self.centre, axis=1).max())

    @functools.cached_property
    def hull_vertices(self) -> np.ndarray:
        """(K, 3) vertices of the convex hull, metres, model frame."""
        return self.vertices[ConvexHull(self.vertices).vertices]

    @property
    def solidity(self) -> float:
        """Mesh volume / convex-hull volume (1 for convex shapes)."""
        return self.volume_m3 / self.hull_volume_m3


# --------------------------------------------------------------------------------------------
# YCB


def resolve_ycb_folder(models_dir: Path | None) -> Path | None:
    """The YCB folder holding ``models/*.ply`` and ``models_info.json``, or None if absent.

    ``models_dir`` may name that folder or its ``models/`` sub-folder.
    """
    if models_dir is None:
        return None
    folder = Path(models_dir)
    if (folder / "models").is_dir() and any((folder / "models").glob("*.ply")):
        return folder
    if (
        folder.is_dir()
        and any(folder.glob("*.ply"))
        and (folder.parent / "models_info.json").is_file()
    ):
        return folder.parent
    return None


@functools.lru_cache(maxsize=4)
def load_ycb_catalogue(folder: str) -> tuple[ObjectModel, ...]:
    """Every YCB object of ``folder`` (see ``resolve_ycb_folder``), ids by sorted file name."""
    import trimesh

    root = Path(folder)
    info_path = root / "models_info.json"
    info = json.loads(info_path.read_text(encoding="utf-8")) if info_path.is_file() else {}
    objects = []
    for index, path in enumerate(sorted((root / "models").glob("*.ply")), start=1):
        mesh = trimesh.load(path, process=False)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int32)
        colors = _vertex_colors(mesh, len(vertices))
        entry = info.get(path.stem, {})
        volume = float(entry.get("volume_m3") or abs(mesh.volume))
        hull_volume = float(ConvexHull(vertices).volume)
        mass = float(entry.get("mass_kg") or 0.0)
        objects.append(
            ObjectModel(index, path.stem, vertices, faces, colors, mass, hull_volume, volume, "ycb")
        )
    return tuple(objects)


def _vertex_colors(mesh, count: int) -> np.ndarray:
    colors = getattr(mesh.visual, "vertex_colors", None)
    if colors is None or len(colors) != count:
        return np.full((count, 3), 180, dtype=np.uint8)
    return np.asarray(colors, dtype=np.uint8)[:, :3].copy()


def ycb_pool(catalogue: tuple[ObjectModel, ...], config: SynthConfig) -> list[ObjectModel]:
    """Objects of ``catalogue`` that pass the pool rule of this module's docstring, then those
    named in ``config.extra_objects`` (ValueError naming any that the catalogue lacks)."""
    by_name = {item.name: item for item in catalogue}
    unknown = [name for name in config.extra_objects if name not in by_name]
    if unknown:
        raise ValueError(
            f"extra_objects {unknown} are not in the YCB catalogue (known: {sorted(by_name)})"
        )
    pool = []
    low, high = config.density_range_kg_m3
    for item in catalogue:
        extents = item.extents
        density = item.mass_kg / item.volume_m3 if item.volume_m3 > 0 else 0.0
        if (
            item.solidity >= config.min_solidity
            and extents.min() >= config.min_extent_m
            and extents.max() <= config.max_extent_m
            and low <= density <= high
        ):
            pool.append(item)
    return pool + [by_name[name] for name in config.extra_objects]


# --------------------------------------------------------------------------------------------
# Procedural shapes

_PALETTE = np.array(
    [
        [200, 40, 40],
        [40, 150, 60],
        [40, 80, 190],
        [230, 190, 40],
        [230, 120, 30],
        [140, 60, 160],
        [30, 160, 170],
        [220, 220, 210],
        [90, 60, 40],
        [200, 90, 140],
        [120, 170, 40],
        [60, 60, 70],
    ],
    dtype=np.float64,
)


@functools.lru_cache(maxsize=8)
def procedural_catalogue(density_range_kg_m3: tuple[float, float]) -> tuple[ObjectModel, ...]:
    """A fixed set of ``PROCEDURAL_COUNT`` boxes, cylinders and spheres of varied sizes/colours.

    Meshes are subdivided so that per-vertex colours can carry a stripe; masses are density x
    volume with one density per shape inside ``density_range_kg_m3``. Shapes and colours come
    from a fixed seed: they are the same in every run and for every density range.
    """
    import trimesh

    rng = np.random.default_rng(PROCEDURAL_SEED)
    objects = []
    for k in range(PROCEDURAL_COUNT):
        shape = ("box", "cylinder", "sphere")[k % 3]
        if shape == "box":
            size = np.sort(rng.uniform(0.035, 0.13, 3))[::-1]
            mesh = trimesh.creation.box(extents=size)
            for _ in range(3):
                mesh = mesh.subdivide()
        elif shape == "cylinder":
            radius = rng.uniform(0.025, 0.05)
            mesh = trimesh.creation.cylinder(
                radius=radius, height=rng.uniform(0.05, 0.15), sections=48
            )
            mesh = mesh.subdivide()
        else:
            mesh = trimesh.creation.icosphere(subdivisions=3, radius=rng.uniform(0.025, 0.045))
        # Model frame like YCB's: origin at the bottom centre, z up.
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        vertices = vertices - [0.0, 0.0, vertices[:, 2].min()]
        base = _PALETTE[k % len(_PALETTE)]
        stripe = _PALETTE[(k * 5 + 3) % len(_PALETTE)]
        height = vertices[:, 2] / max(vertices[:, 2].max(), 1e-9)
        in_stripe = (height > 0.55) & (height < 0.75)
        shade = 1.0 + rng.normal(0.0, 0.03, (len(vertices), 1))
        colors = np.where(in_stripe[:, None], stripe, base) * shade
        colors = np.clip(np.round(colors), 0, 255).astype(np.uint8)
        volume = float(abs(mesh.volume))
        low, high = density_range_kg_m3
        density = low + rng.uniform() * (high - low)
        faces = np.asarray(mesh.faces, dtype=np.int32)
        hull_volume = float(ConvexHull(vertices).volume)
        objects.append(
            ObjectModel(
                PROCEDURAL_FIRST_ID + k,
                f"{shape}_{k:02d}",
                vertices,
                faces,
                colors,
                float(density * volume),
                hull_volume,
                volume,
                "procedural",
            )
        )
    return tuple(objects)


# --------------------------------------------------------------------------------------------
# BOP export


def ply_bytes_mm(item: ObjectModel) -> bytes:
    """Binary little-endian PLY of the model in millimetres with per-vertex normals and RGB."""
    import trimesh

    mesh = trimesh.Trimesh(item.vertices, item.faces, process=False)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float32)
    vertex = np.zeros(
        len(item.vertices),
        dtype=[
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("nx", "<f4"),
            ("ny", "<f4"),
            ("nz", "<f4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
        ],
    )
    millimetres = (item.vertices * 1000.0).astype(np.float32)
    vertex["x"], vertex["y"], vertex["z"] = millimetres.T
    vertex["nx"], vertex["ny"], vertex["nz"] = normals.T
    vertex["red"], vertex["green"], vertex["blue"] = item.colors.T
    face = np.zeros(len(item.faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face["n"] = 3
    face["v"] = item.faces
    return _ply_header(item).encode("ascii") + vertex.tobytes() + face.tobytes()


def _ply_header(item: ObjectModel) -> str:
    return (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment ipr_shapes.synth model {item.name}, millimetres\n"
        f"element vertex {len(item.vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {len(item.faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )


def _ply_size(item: ObjectModel) -> int:
    """Byte size of ``ply_bytes_mm(item)`` without building it."""
    header = len(_ply_header(item).encode("ascii"))
    return header + 27 * len(item.vertices) + 13 * len(item.faces)


def bop_model_info(item: ObjectModel) -> dict[str, float | str]:
    """BOP ``models_info.json`` entry (millimetres) plus the object's ``name``."""
    hull = item.hull_vertices * 1000.0
    low = item.vertices.min(axis=0) * 1000.0
    size = item.extents * 1000.0
    squared_norms = (hull**2).sum(axis=1)
    diameter_sq = 0.0
    for start in range(0, len(hull), 1024):  # chunked |a|^2 + |b|^2 - 2 a.b (hulls are big)
        block = hull[start : start + 1024]
        squared = (
            squared_norms[start : start + 1024, None] + squared_norms[None] - 2 * (block @ hull.T)
        )
        diameter_sq = max(diameter_sq, float(squared.max()))
    diameter = float(np.sqrt(max(diameter_sq, 0.0)))
    return {
        "diameter": round(diameter, 6),
        "min_x": round(float(low[0]), 6),
        "min_y": round(float(low[1]), 6),
        "min_z": round(float(low[2]), 6),
        "size_x": round(float(size[0]), 6),
        "size_y": round(float(size[1]), 6),
        "size_z": round(float(size[2]), 6),
        "name": item.name,
    }


def _atomic_write(path: Path, content: bytes) -> None:
    """Write ``content`` to a temporary file beside ``path``, then rename it into place."""
    descriptor, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(content)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # mkstemp makes the file private; models are shared
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def write_bop_models(models_out: Path, objects: list[ObjectModel]) -> None:
    """Write ``obj_NNNNNN.ply`` (mm) and merge ``models_info.json`` in ``models_out``.

    Files already present with identical bytes are left alone; every write is atomic (temporary
    file, then ``os.replace``), so scenes generated concurrently can share the folder. Raises
    ValueError when the folder already holds a different object under one of the ids.
    """
    models_out.mkdir(parents=True, exist_ok=True)
    info_path = models_out / "models_info.json"
    info: dict[str, dict] = {}
    if info_path.is_file():
        try:
            info = json.loads(info_path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError):
            info = {}
    merged = dict(info)
    for item in objects:
        key = str(item.obj_id)
        previous = info.get(key)
        if previous is not None and previous.get("name") not in (None, item.name):
            raise ValueError(
                f"{models_out} already holds object {item.obj_id} named {previous.get('name')!r}, "
                f"not {item.name!r}; write these scenes to another folder"
            )
        path = models_out / f"obj_{item.obj_id:06d}.ply"
        if previous is not None and path.is_file() and path.stat().st_size == _ply_size(item):
            continue  # written by an earlier scene: same id, name and size
        content = ply_bytes_mm(item)
        if not (path.is_file() and path.read_bytes() == content):
            _atomic_write(path, content)
        merged[key] = bop_model_info(item)
    if merged != info:
        ordered = {key: merged[key] for key in sorted(merged, key=int)}
        _atomic_write(info_path, (json.dumps(ordered, indent=1) + "\n").encode("utf-8"))
