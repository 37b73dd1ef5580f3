"""Generation of benchmark scenes: sample, simulate, render, add sensor noise, write.

One scene = one deterministic sequence of attempts: attempt ``a`` of seed ``s`` draws everything
(objects, arrangement geometry, drops, camera, pushes, noise) from
``np.random.SeedSequence(s, spawn_key=(a,))``. An attempt is rejected, and the next one tried,
when objects leave the table or container, contacts penetrate, the pile does not settle or does
not hold together, fewer than ``min_visible_objects`` objects are visible in frame 0, the drawer
front hides too little of the pile, or no valid push is found. Same seed, same files.
"""

from __future__ import annotations

import io
import json
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

import ipr_shapes
from ipr_shapes.camera import invert_transform
from ipr_shapes.data import ycb_models_dir
from ipr_shapes.errors import IprError, SceneError
from ipr_shapes.scene import Frame, ObjectPose, Push, Pusher, write_scene
from ipr_shapes.synth.catalogue import (
    ObjectModel,
    load_ycb_catalogue,
    procedural_catalogue,
    resolve_ycb_folder,
    write_bop_models,
    ycb_pool,
)
from ipr_shapes.synth.config import ARRANGEMENTS, KINDS, SynthConfig
from ipr_shapes.synth.piles import LABEL_FRONT_WALL, PileWorld, Rejected, sample_layout
from ipr_shapes.synth.preview import preview_png
from ipr_shapes.synth.pushes import plan_and_push
from ipr_shapes.synth.render import RenderedFrame, SceneRenderer
from ipr_shapes.synth.sensor import camera_pose, noisy_depth, noisy_rgb, sample_intrinsics

SYNTH_FORMAT = "ipr-synth/1"


class GenerationError(IprError):
    """No acceptable configuration was found within ``SynthConfig.max_attempts``."""


@dataclass(frozen=True, eq=False)
class _Generated:
    """Everything an accepted attempt produced, ready to be written."""

    frames: list[Frame]
    labels: list[np.ndarray]
    clean_depth: list[np.ndarray]
    pushes: list[Push]
    ground_truth: dict[int, list[ObjectPose]]
    info: dict[int, list[dict[str, Any]]]
    metadata: dict[str, Any]


# --------------------------------------------------------------------------------------------
# Public API


def generate_scene(
    out_dir: Path | str,
    *,
    kind: str,
    seed: int,
    arrangement: str | None = None,
    models_dir: Path | str | None = None,
    config: SynthConfig = SynthConfig(),  # noqa: B008 (frozen, so a shared default is safe)
    name: str | None = None,
    overwrite: bool = False,
) -> Path:
    """Generate one scene folder ``out_dir/<name>`` and the shared BOP models in
    ``out_dir/models``; return the scene's path.

    Args:
        out_dir: parent folder of the scene and of ``models/``.
        kind: "static" (no robot action) or "dynamic" (pushes between frames).
        seed: non-negative integer; the same seed and config give byte-identical files.
        arrangement: "table", "container" or "drawer"; None draws one from the seed.
        models_dir: YCB source folder (``<id>_<name>.ply`` in metres under ``models/``, with
            ``models_info.json``); default ``ipr_shapes.data.ycb_models_dir()``. When no YCB folder is
            found, procedural boxes, cylinders and spheres are used (``config.object_source``
            can force either source).
        config: generator settings.
        name: scene folder name, default ``f"{kind}_{seed:06d}"``.
        overwrite: replace an existing scene folder.

    Raises:
        ValueError: invalid arguments or settings.
        SceneError: the scene folder exists and ``overwrite`` is False.
        GenerationError: no acceptable configuration within ``config.max_attempts``.
    """
    _check_kind(kind)
    seed = _check_seed(seed)
    if arrangement is not None and arrangement not in ARRANGEMENTS:
        raise ValueError(f"arrangement must be one of {ARRANGEMENTS} or None, got {arrangement!r}")
    if not isinstance(config, SynthConfig):
        raise ValueError(f"config must be a SynthConfig, got {type(config).__name__}")
    config.validate()
    name = f"{kind}_{seed:06d}" if name is None else name
    _check_name(name)
    out_dir = Path(out_dir)
    target = out_dir / name
    if target.exists() and not overwrite:
        raise SceneError(target, "already exists", "choose another name or pass overwrite=True")
    pool, source = object_pool(models_dir, config)
    if arrangement is None:
        chooser = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2**31,)))
        arrangement = ARRANGEMENTS[int(chooser.integers(len(ARRANGEMENTS)))]

    rejections: list[str] = []
    generated = None
    for attempt in range(config.max_attempts):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(attempt,)))
        try:
            generated = _attempt(kind, arrangement, pool, config, rng)
        except Rejected as reason:
            rejections.append(f"attempt {attempt}: {reason}")
            continue
        break
    if generated is None:
        raise GenerationError(
            f"no acceptable {arrangement} scene for seed {seed} in {config.max_attempts} attempts "
            f"(last reasons: {'; '.join(rejections[-3:])}); try another seed or relax SynthConfig"
        )

    write_bop_models(out_dir / "models", pool)
    metadata = {
        "format": SYNTH_FORMAT,
        "generator": f"ipr {ipr_shapes.__version__} ipr_shapes.synth",
        "kind": kind,
        "arrangement": arrangement,
        "seed": seed,
        "object_source": source,
        "attempts": len(rejections) + 1,
        "rejected": rejections,
        **generated.metadata,
        "config": _jsonable(asdict(config)),
    }
    extra: dict[str, bytes] = {"synth.json": _json_bytes(metadata)}
    if config.write_preview:
        title = f"{name}: {kind} {arrangement}, {len(generated.ground_truth[0])} objects"
        obj_ids = [pose.obj_id for pose in generated.ground_truth[0]]
        extra["preview.png"] = preview_png(
            generated.frames,
            generated.labels,
            obj_ids,
            generated.pushes,
            config.preview_width_px,
            title,
            pusher_drop_m=config.pusher_length_m / 2 - config.pusher_radius_m,
        )
    if config.write_clean_depth:
        for index, clean in enumerate(generated.clean_depth):
            units = np.clip(np.round(clean.astype(np.float64) * 1000.0), 0, 65535)
            extra[f"depth_clean/{index:06d}.png"] = _png_bytes(units.astype(np.uint16))
    pusher = None
    if kind == "dynamic":
        pusher = Pusher(config.pusher_radius_m, config.pusher_length_m, np.array([0.0, 0.0, 1.0]))
    return write_scene(
        target,
        generated.frames,
        pushes=generated.pushes,
        pusher=pusher,
        depth_scale=1.0,
        write_poses=True,
        ground_truth=generated.ground_truth,
        ground_truth_info=generated.info,
        overwrite=overwrite,
        extra_files=extra,
    )


def generate_scenes(
    out_dir: Path | str,
    *,
    kind: str,
    seed: int,
    count: int,
    config: SynthConfig = SynthConfig(),  # noqa: B008
    models_dir: Path | str | None = None,
    progress: Callable[[int, int], None] | None = None,
    overwrite: bool = False,
) -> list[Path]:
    """Generate ``count`` scenes ``out_dir/<kind>_<i:06d>`` sharing ``out_dir/models``.

    Scene ``i`` uses the seed ``SeedSequence(seed, spawn_key=(i,)).generate_state(1)[0]`` (so a
    scene does not depend on ``count``) and the arrangement ``ARRANGEMENTS[i % 3]`` (table,
    container, drawer, table, ...). ``progress(done, count)`` is called after each scene.
    """
    _check_kind(kind)
    seed = _check_seed(seed)
    if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 1:
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    if not isinstance(config, SynthConfig):
        raise ValueError(f"config must be a SynthConfig, got {type(config).__name__}")
    config.validate()
    paths = []
    for index in range(int(count)):
        paths.append(
            generate_scene(
                out_dir,
                kind=kind,
                seed=scene_seed(seed, index),
                arrangement=ARRANGEMENTS[index % len(ARRANGEMENTS)],
                models_dir=models_dir,
                config=config,
                name=f"{kind}_{index:06d}",
                overwrite=overwrite,
            )
        )
        if progress is not None:
            progress(index + 1, int(count))
    return paths


def scene_seed(seed: int, index: int) -> int:
    """Seed of scene ``index`` of a suite generated with ``seed``."""
    return int(np.random.SeedSequence(seed, spawn_key=(index,)).generate_state(1)[0])


def object_pool(
    models_dir: Path | str | None, config: SynthConfig
) -> tuple[list[ObjectModel], str]:
    """The objects scenes draw from and their source ("ycb" or "procedural").

    Raises ValueError when ``object_source`` is "ycb" but no YCB folder is found, or when the
    YCB pool rule leaves fewer than ``min_objects`` objects.
    """
    requested = Path(models_dir) if models_dir is not None else ycb_models_dir()
    folder = resolve_ycb_folder(requested) if config.object_source != "procedural" else None
    if config.object_source == "ycb" and folder is None:
        raise ValueError(
            f"no YCB models found in {requested} (expected models/*.ply and "
            "models_info.json); pass models_dir or use object_source='procedural'"
        )
    if folder is None:
        if config.object_source == "auto" and models_dir is not None:
            warnings.warn(f"no YCB models in {models_dir}; using procedural objects", stacklevel=3)
        return list(procedural_catalogue(tuple(config.procedural_density_kg_m3))), "procedural"
    pool = ycb_pool(load_ycb_catalogue(str(folder.resolve())), config)
    if len(pool) < config.min_objects:
        raise ValueError(
            f"only {len(pool)} YCB objects in {folder} pass the pool rule, fewer "
            f"than min_objects={config.min_objects}; relax min_solidity/extents"
        )
    return pool, "ycb"


# --------------------------------------------------------------------------------------------
# One attempt


def _attempt(
    kind: str,
    arrangement: str,
    pool: list[ObjectModel],
    config: SynthConfig,
    rng: np.random.Generator,
) -> _Generated:
    if arrangement != "table":
        pool = [item for item in pool if item.extents.max() <= config.boxed_max_extent_m] or pool
    count = min(int(rng.integers(config.min_objects, config.max_objects + 1)), len(pool))
    objects = [pool[i] for i in rng.choice(len(pool), count, replace=False)]
    layout = sample_layout(arrangement, objects, rng, config)
    frictions = rng.uniform(*config.friction, count)
    light_azimuth, light_elevation = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(50, 80))
    light_dir = -np.array(
        [
            np.cos(light_elevation) * np.cos(light_azimuth),
            np.cos(light_elevation) * np.sin(light_azimuth),
            np.sin(light_elevation),
        ]
    )
    world = PileWorld(layout, objects, frictions, config, light_dir)
    world.drop_all(rng)

    # Camera: looks at the centre of the pile's bounding box.
    bounds = world.pile_bounds()
    target = bounds.mean(axis=0)
    distance = rng.uniform(*config.camera_distance_m)
    if arrangement == "drawer":
        elevation = rng.uniform(*config.drawer_elevation_deg)
    else:
        elevation = rng.uniform(*config.camera_elevation_deg)
    azimuth = rng.uniform(*(layout.camera_azimuth_deg or (-180.0, 180.0)))
    K = sample_intrinsics(rng, config)
    world_from_camera = camera_pose(target, distance, elevation, azimuth)

    pushes: list[Push] = []
    displacements: list[float] = []
    with SceneRenderer(world, K, world_from_camera) as renderer:
        rendered = [renderer.render(world.data.qpos)]
        visible = _visible(rendered[0], count, config)
        if visible.size < config.min_visible_objects:
            raise Rejected(f"only {visible.size} objects visible in frame 0")
        occluded_fraction = None
        if arrangement == "drawer":
            objects_only = renderer.objects_only_labels(world.data.qpos) >= 0
            hidden = objects_only & (rendered[0].labels == LABEL_FRONT_WALL)
            occluded_fraction = float(hidden.sum() / max(objects_only.sum(), 1))
            if occluded_fraction < config.drawer_min_occluded_fraction:
                raise Rejected(f"the drawer front hides only {occluded_fraction:.0%} of the pile")
        solo = [renderer.solo_masks(world.data.qpos)]
        if kind == "dynamic":
            for index in range(int(rng.integers(config.pushes[0], config.pushes[1] + 1))):
                push, moved = plan_and_push(world, visible, rng, index)
                pushes.append(push)
                displacements.append(moved)
                rendered.append(renderer.render(world.data.qpos))
                solo.append(renderer.solo_masks(world.data.qpos))
                visible = _visible(rendered[-1], count, config)
                if visible.size == 0:
                    raise Rejected(f"no object visible after push {index}")
        else:
            rendered *= config.static_frames
            solo *= config.static_frames

    frames, ground_truth, info = [], {}, {}
    camera_from_world = invert_transform(world_from_camera)
    for index, (render, masks) in enumerate(zip(rendered, solo, strict=True)):
        depth = noisy_depth(render.depth_m, rng, config)
        rgb = noisy_rgb(render.rgb, rng, config)
        frames.append(Frame(index, rgb, depth, K, world_from_camera))
        ground_truth[index] = [
            ObjectPose(item.obj_id, camera_from_world @ render.poses[i])
            for i, item in enumerate(objects)
        ]
        info[index] = [_gt_info(masks[i], render.labels == i, depth) for i in range(count)]

    metadata = {
        "camera": {
            "target_m": target.tolist(),
            "distance_m": float(distance),
            "elevation_deg": float(elevation),
            "azimuth_deg": float(azimuth),
        },
        "objects": [
            {
                "obj_id": item.obj_id,
                "name": item.name,
                "mass_kg": float(item.mass_kg),
                "friction": float(frictions[i]),
            }
            for i, item in enumerate(objects)
        ],
        "support": {
            "table_half_extents_m": layout.table_half_m.tolist(),
            "region_half_extents_m": layout.region_half_m.tolist(),
            "walls": [
                {
                    "name": w.name,
                    "centre_m": w.centre.tolist(),
                    "half_size_m": w.half_size.tolist(),
                    "front": w.front,
                }
                for w in layout.walls
            ],
        },
        "drawer_occluded_fraction": occluded_fraction,
        "push_max_displacement_m": displacements,
    }
    return _Generated(
        frames,
        [r.labels for r in rendered],
        [r.depth_m for r in rendered],
        pushes,
        ground_truth,
        info,
        metadata,
    )


def _visible(render: RenderedFrame, count: int, config: SynthConfig) -> np.ndarray:
    """Indices of objects with at least ``min_visible_px`` pixels in ``render``."""
    labels = render.labels[render.labels >= 0]
    pixels = np.bincount(labels, minlength=count)
    return np.flatnonzero(pixels >= config.min_visible_px)


def _bbox(mask: np.ndarray) -> list[int]:
    """BOP bounding box [x, y, width, height] of a mask, or [-1, -1, -1, -1] when empty."""
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return [-1, -1, -1, -1]
    return [
        int(cols.min()),
        int(rows.min()),
        int(cols.max() - cols.min() + 1),
        int(rows.max() - rows.min() + 1),
    ]


def _gt_info(solo: np.ndarray, visible: np.ndarray, depth: np.ndarray) -> dict[str, Any]:
    """BOP ``scene_gt_info`` entry of one object in one frame."""
    all_px, visible_px = int(solo.sum()), int(visible.sum())
    return {
        "bbox_obj": _bbox(solo),
        "bbox_visib": _bbox(visible),
        "px_count_all": all_px,
        "px_count_valid": int((visible & (depth > 0)).sum()),
        "px_count_visib": visible_px,
        "visib_fract": round(visible_px / all_px, 6) if all_px else 0.0,
    }


# --------------------------------------------------------------------------------------------
# Helpers


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_name(name: str) -> None:
    if (
        not isinstance(name, str)
        or not name
        or name in (".", "..", "models")
        or "/" in name
        or "\\" in name
    ):
        raise ValueError(f"name must be a plain folder name other than 'models', got {name!r}")


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _jsonable(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(item) for item in value]
    return value


def _json_bytes(content: Any) -> bytes:
    return (json.dumps(content, indent=1, allow_nan=False) + "\n").encode("utf-8")


def _png_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return buffer.getvalue()
