"""Exports of a result that robot stacks load directly: an MJCF scene (MuJoCo), a URDF per object
(pybullet, MoveIt, MuJoCo), SDF (Gazebo), OBJ meshes and a GLB scene for viewers.

Per object (``ipr_shapes.export.model``): a smooth closed surface rebuilt from the result's 5 mm voxel
shape (``ipr_shapes.export.surface``), in an object frame at its centre of mass with the world's
axes; its pose; convex collision pieces (its convex hull, or CoACD's decomposition) and
their mass and inertia at a uniform density (400 kg/m^3 by default, the inference's). The scene
(``ipr_shapes.export.placement``): the support plane, the walls the result records (static convex
slabs) and the objects' start poses, separated where they interpenetrate, then settled in
MuJoCo. Files and frames: ``ipr_shapes.export.formats`` and
docs/FORMATS.md.

    from ipr_shapes.export import export_result
    export_result("result/", "robot/", format="mjcf")   # robot/scene.xml, meshes/, export.json
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from ipr_shapes.atomic import staged_directory, write_json
from ipr_shapes.errors import IprError, ResultError
from ipr_shapes.export.formats import FORMATS, MANIFEST, WRITERS, manifest
from ipr_shapes.export.model import (
    COLLISION_METHODS,
    CollisionUnavailable,
    ExportConfig,
    ObjectBody,
    object_body,
    require_collision_method,
)
from ipr_shapes.export.placement import SceneBodies, scene_bodies
from ipr_shapes.result import Result, load_result

__all__ = [
    "COLLISION_METHODS",
    "FORMATS",
    "ExportConfig",
    "ObjectBody",
    "SceneBodies",
    "build_scene",
    "default_out_dir",
    "export_result",
    "load_export_manifest",
]

log = logging.getLogger(__name__)


def load_export_manifest(out_dir: Path | str) -> dict:
    """The parsed ``export.json`` of an export folder."""
    import json

    return json.loads((Path(out_dir) / MANIFEST).read_text(encoding="utf-8"))


def default_out_dir(result_path: Path | str, export_format: str) -> Path:
    """Where ``export_result`` writes without ``out_dir``: ``RESULT/export/<format>``."""
    return Path(result_path) / "export" / export_format


def build_scene(result: Result | Path | str, config: ExportConfig | None = None) -> SceneBodies:
    """The rigid bodies and support of a result (a loaded ``Result`` or its folder), in memory.

    Raises ResultError for a result that is malformed, has no objects, or holds a shape that
    cannot be a body (no volume, absurd size), IprError when the collision method's package is
    missing.
    """
    config = config or ExportConfig()
    if not isinstance(result, Result):
        result = load_result(result)
    if not result.objects:
        raise ResultError(
            result.path / "result.json", "the result has no objects: nothing to export"
        )
    bodies: list[ObjectBody] = []
    for item in result.objects:
        try:
            body = object_body(item.id, item.load_mesh(), item.probability, config)
        except ValueError as error:
            raise ResultError(
                item.mesh_path, f"object {item.id}: {error}", "check the mesh's units"
            ) from None
        except CollisionUnavailable as error:
            raise IprError(str(error)) from None
        log.info(
            "%s: %s surface %.2f s (%d faces, volume %+.2f %%), %d collision piece(s) %.2f s",
            body.name,
            body.surface_source,
            body.timing_s["surface"],
            len(body.surface.faces),
            100 * (body.volume_error or 0.0),
            len(body.collision),
            body.timing_s["collision"],
        )
        bodies.append(body)
    return scene_bodies(bodies, config, walls=result_walls(result))


#: Walls farther than this from the world origin (m) are taken for a unit error.
MAX_WALL_REACH_M = 100.0


def result_walls(result: Result) -> tuple[np.ndarray, ...]:
    """The walls a result records (``result.json``'s ``walls``: per wall the (V, 3) vertices, m,
    world frame, of the convex slab the inference simulated); () when it records none (results
    from before, or from other tools). ResultError names a malformed entry."""
    raw = result.extra.get("walls", [])
    where = result.path / "result.json"
    if not isinstance(raw, list):
        raise ResultError(where, f"'walls' must be a list, got {type(raw).__name__}")
    walls = []
    for k, entry in enumerate(raw):
        vertices = entry.get("vertices_m") if isinstance(entry, dict) else None
        try:
            array = np.asarray(vertices, dtype=np.float64)
        except (TypeError, ValueError):
            array = np.zeros((0,))
        if array.ndim != 2 or array.shape[1:] != (3,) or len(array) < 4:
            raise ResultError(
                where,
                f"walls[{k}].vertices_m must be a list of at least 4 [x, y, z] points",
                "write each wall's slab vertices in metres, or leave 'walls' out",
            )
        if not np.isfinite(array).all() or np.abs(array).max() > MAX_WALL_REACH_M:
            raise ResultError(
                where,
                f"walls[{k}].vertices_m holds a non-finite value or a point more than "
                f"{MAX_WALL_REACH_M:g} m from the origin",
                "write the vertices in metres in the result's world frame",
            )
        spread = np.linalg.svd(array - array.mean(axis=0), compute_uv=False)
        if spread[-1] < 1e-6:
            raise ResultError(
                where,
                f"walls[{k}] is flat or a line (its vertices enclose no volume)",
                "give the slab's back face too (the wall's thickness)",
            )
        walls.append(array)
    return tuple(walls)


def export_result(
    result_path: Path | str,
    out_dir: Path | str | None = None,
    format: str = "mjcf",  # noqa: A002 - the CLI's --format
    *,
    density_kg_m3: float | None = None,
    collision: str | None = None,
    settle: bool | None = None,
    config: ExportConfig | None = None,
    overwrite: bool = False,
) -> Path:
    """Export the result folder ``result_path`` as ``format`` (``FORMATS``) into ``out_dir``
    (default ``RESULT/export/<format>``); returns ``out_dir``.

    ``density_kg_m3``, ``collision`` (``"hull"`` or ``"coacd"``) and ``settle`` override
    ``config``'s.
    The folder is written beside its place and renamed into it, so it is either complete or
    absent. Raises ValueError for a bad argument, ResultError for a bad result or an output
    folder that exists (without ``overwrite``) or would replace the result, IprError when the
    collision method's package is missing.
    """
    if format not in WRITERS:
        raise ValueError(f"unknown export format {format!r}: choose one of {', '.join(FORMATS)}")
    config = config or ExportConfig()
    changes = {}
    if density_kg_m3 is not None:
        changes["density_kg_m3"] = density_kg_m3
    if collision is not None:
        changes["collision"] = collision
    if settle is not None:
        changes["settle"] = bool(settle)
    config = dataclasses.replace(config, **changes)  # ValueError for a bad value
    source = Path(result_path)
    target = Path(out_dir) if out_dir is not None else default_out_dir(source, format)
    _check_target(source, target, overwrite)
    try:
        require_collision_method(config)
    except CollisionUnavailable as error:
        raise IprError(str(error)) from None
    started = time.perf_counter()
    result = load_result(source)
    loaded = time.perf_counter()
    scene = build_scene(result, config)
    built = time.perf_counter()
    with staged_directory(target) as staging:
        files = WRITERS[format](staging, scene, config)
        timing = {
            "load": loaded - started,
            "bodies": built - loaded,
            "write": time.perf_counter() - built,
        }
        origin = {"result": str(result.path.resolve()), "method": result.method}
        write_json(staging / MANIFEST, manifest(scene, config, format, files, origin, timing))
    log.info(
        "exported %d objects as %s in %.1f s", len(scene.objects), format, sum(timing.values())
    )
    return target


def _check_target(source: Path, target: Path, overwrite: bool) -> None:
    """Refuse an output folder that exists (without ``overwrite``) or that is the result or holds
    it (replacing it would delete the result)."""
    resolved_source = source.resolve()
    resolved_target = target.resolve()
    if resolved_target == resolved_source or resolved_target in resolved_source.parents:
        raise ResultError(
            target,
            "the output folder is the result or holds it; exporting there would replace it",
            "choose another folder (default: RESULT/export/<format>)",
        )
    if target.exists() and not overwrite:
        raise ResultError(target, "already exists", "choose another folder or pass --overwrite")
    if target.exists() and not target.is_dir():
        raise ResultError(target, "is a file, not a folder", "choose a folder path")
    existing = next(parent for parent in resolved_target.parents if parent.exists())
    if not existing.is_dir():
        raise ResultError(target, f"{existing} is a file, not a folder", "choose a folder path")
