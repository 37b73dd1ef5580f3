"""The main job: a scene directory in, a result directory out (what ``ipr infer`` runs).

``run_pipeline(scene, config, method=...)`` is the one entry point the CLI and the Python API
share: perception of every frame, hypotheses for the objects of frame 0 (the initial scene the
result describes), then the chosen inference method.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ipr.config import Config
from ipr.errors import IprError
from ipr.scene import Scene, load_scene

log = logging.getLogger(__name__)

#: Inference methods available now (the physics-based methods arrive with the physics stage).
METHODS = ("collision-checker",)


@dataclass(frozen=True, eq=False)
class PipelineResult:
    """What a run produced: per-object posteriors, the perception, and seconds per stage."""

    method: str
    posteriors: list
    perception: object
    timing_s: dict[str, float]


def run_pipeline(
    scene: Scene,
    config: Config | None = None,
    *,
    method: str = "collision-checker",
    seed: int = 0,
    time_budget_s: float | None = None,
) -> PipelineResult:
    """Perceive the scene and infer complete shapes of the objects of frame 0."""
    from ipr.collision_checker import collision_checker
    from ipr.perception import perceive_scene

    if method not in METHODS:
        raise IprError(f"unknown method {method!r}; available: {', '.join(METHODS)}")
    if time_budget_s is not None and time_budget_s <= 0:
        raise IprError(f"--time-budget must be positive, got {time_budget_s}")
    config = config or Config()
    started = time.perf_counter()
    perception = perceive_scene(scene, config.perception)
    perceived = time.perf_counter()
    objects = perception.objects[0]
    if not objects:
        log.warning("%s: no object found in frame 0; the result is empty", scene.path)
    remaining = None if time_budget_s is None else max(time_budget_s - (perceived - started), 1e-3)
    posteriors = collision_checker(
        objects,
        perception.free_space[0],
        perception.planes[0],
        config.collision_checker,
        rng=np.random.default_rng(seed),
        time_budget_s=remaining,
    )
    finished = time.perf_counter()
    generation = float(sum(p.generation_s for p in posteriors))
    timing = {
        "segmentation": perceived - started,
        "hypotheses": generation,
        "inference": max(finished - perceived - generation, 0.0),
        "total": finished - started,
    }
    return PipelineResult(method, posteriors, perception, timing)


def infer(
    scene_path: Path | str,
    out_dir: Path | str,
    *,
    method: str = "collision-checker",
    seed: int = 0,
    time_budget_s: float | None = None,
    config: Config | None = None,
    overwrite: bool = False,
) -> Path:
    """Load a scene, run the pipeline and write the result directory (atomically)."""
    from ipr.collision_checker import write_collision_checker_result

    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise IprError(
            f"{out_dir}: already exists (fix: choose another folder or pass --overwrite)"
        )
    scene = load_scene(scene_path)
    result = run_pipeline(scene, config, method=method, seed=seed, time_budget_s=time_budget_s)
    world_from_camera = {frame.index: frame.world_from_camera for frame in scene.frames}
    return write_collision_checker_result(
        out_dir, result.posteriors, world_from_camera, result.timing_s, overwrite=overwrite
    )
