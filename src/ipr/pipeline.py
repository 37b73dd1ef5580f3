"""The main job: a scene directory in, a result directory out (what ``ipr infer`` runs).

``run_pipeline(scene, config, method=...)`` is the one entry point the CLI and the Python API
share: perception of every frame, hypotheses for the objects of frame 0 (the initial scene the
result describes), then the chosen inference method: the Collision Checker, or one of the
physics-based methods of ``ipr.inference`` (default ``ipr+action+uniform``, the full method).
The methods that use the pushes' evidence (``+action`` and ``exhaustive``) also register what
the later frames saw of each object into frame 0 (``ipr.fusion``) before the hypotheses; the
others see frame 0 only, as their likelihood does.

Time budget: ``time_budget_s`` covers the whole run; hypotheses get their share of what is left
after perception and fusion (a per-object timeout), and inference the rest. Without one,
hypotheses have no wall-clock limit (so they do not depend on the machine's load) and inference
gets ``config.inference.budget_per_object_s`` per object, less what fusion took per object (at
most half of it).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ipr.config import Config
from ipr.errors import IprError
from ipr.methods import DEFAULT_METHOD, METHODS
from ipr.scene import Scene, load_scene

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class PipelineResult:
    """What a run produced: per-object posteriors, the perception, seconds per stage, and
    method-specific details (``summary``: samples, fallback, ...)."""

    method: str
    posteriors: list
    perception: object
    timing_s: dict[str, float]
    summary: dict = field(default_factory=dict)


def run_pipeline(
    scene: Scene,
    config: Config | None = None,
    *,
    method: str = DEFAULT_METHOD,
    seed: int = 0,
    time_budget_s: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
) -> PipelineResult:
    """Perceive the scene and infer complete shapes of the objects of frame 0.

    ``samples`` fixes the number of joint models the physics-based methods sample (then only
    ``time_budget_s``, if given, can stop them earlier): the same seed and samples give the
    same result with any number of ``workers``. More than one worker (the default on a
    multi-core machine) starts a process pool: as with any Python multiprocessing, a script
    calling this must guard its entry point with ``if __name__ == "__main__":``.
    """
    from ipr.carving import carve_posteriors, surface_views
    from ipr.collision_checker import collision_checker, prepare_hypotheses
    from ipr.fusion import fuse_views, tracked_free_spaces
    from ipr.inference import VARIANTS, infer_shapes
    from ipr.likelihood import observed_frames
    from ipr.perception import perceive_scene
    from ipr.perception.occlusion import join_first_frame_pieces

    if method not in METHODS:
        raise IprError(f"unknown method {method!r}; available: {', '.join(METHODS)}")
    if time_budget_s is not None and not time_budget_s > 0:
        raise IprError(f"--time-budget must be positive, got {time_budget_s}")
    if workers is not None and workers < 1:
        raise IprError(f"--workers must be at least 1, got {workers}")
    if samples is not None and samples < 1:
        raise IprError(f"--samples must be at least 1, got {samples}")
    config = config or Config()
    if samples is not None:
        config = dataclasses.replace(
            config, inference=dataclasses.replace(config.inference, max_samples=samples)
        )
    started = time.perf_counter()
    deadline = None if time_budget_s is None else started + time_budget_s
    perception = perceive_scene(scene, config.perception)
    perception, _ = join_first_frame_pieces(scene, perception, config.perception.occluded_pieces)
    perceived = time.perf_counter()
    objects = perception.objects[0]
    if not objects:
        log.warning("%s: no object found in frame 0; the result is empty", scene.path)
    summary: dict = {}
    object_spaces: dict = {}
    motions: dict = {}  # per object, its registered later-frame motions (methods with pushes)
    if method in VARIANTS and VARIANTS[method].actions and config.fusion.enabled:
        support = next((p for p in perception.planes[0] if p.kind == "support"), None)
        fused = fuse_views(perception.objects, perception.free_space, support, config.fusion)
        objects = fused.objects
        motions = fused.motions
        if config.fusion.later_free_space or config.fusion.pusher_free_space:
            object_spaces = tracked_free_spaces(
                fused, perception.free_space, scene.pushes, scene.pusher, config.fusion
            )
        # Keyed like the result's objects (their position), listing the later frames fused.
        summary["fused_views"] = {
            str(position): fused.fused_frames[obj.id]
            for position, obj in enumerate(objects)
            if obj.id in fused.fused_frames
        }
    fused_at = time.perf_counter()
    if (
        objects
        and fused_at - perceived > 0
        and deadline is None
        and not config.inference.max_samples
    ):
        # Fusion's time comes out of the default inference budget (at most half of it), so
        # that a default run costs what it did without fusion (about 3 s per object).
        per_object = config.inference.budget_per_object_s
        spent = min((fused_at - perceived) / len(objects), per_object / 2)
        config = dataclasses.replace(
            config,
            inference=dataclasses.replace(config.inference, budget_per_object_s=per_object - spent),
        )
    remaining = None if deadline is None else max(deadline - fused_at, 1e-3)
    rng = np.random.default_rng(seed)
    if method == "collision-checker":
        posteriors = collision_checker(
            objects,
            perception.free_space[0],
            perception.planes[0],
            config.collision_checker,
            rng=rng,
            time_budget_s=remaining,
        )
        finished = time.perf_counter()
        generation = float(sum(p.generation_s for p in posteriors))
        timing = {
            "segmentation": perceived - started,
            "hypotheses": generation,
            "inference": max(finished - perceived - generation, 0.0),
        }
    else:
        prepared = prepare_hypotheses(
            objects,
            perception.free_space[0],
            perception.planes[0],
            config.collision_checker,
            rng,
            remaining,
            object_spaces,
        )
        generated = time.perf_counter()
        observed = observed_frames(
            scene.frames, perception.labels, config.inference.likelihood.decimation
        )
        try:
            outcome = infer_shapes(
                prepared,
                perception.planes[0],
                observed,
                method=method,
                pusher=scene.pusher,
                pushes=scene.pushes,
                config=config.inference,
                collision_checker_config=config.collision_checker,
                seed=seed,
                deadline=deadline,
                workers=workers,
            )
        except IprError as error:  # say which scene the method refused
            raise IprError(f"{scene.path}: {error}") from None
        finished = time.perf_counter()
        posteriors = outcome.posteriors
        summary = {**summary, **outcome.summary}
        timing = {
            "segmentation": perceived - started,
            "fusion": fused_at - perceived,
            "hypotheses": generated - fused_at,
            "inference": finished - generated,
            **{f"inference_{name}": value for name, value in outcome.timing_s.items()},
        }
    if config.carving.enabled and posteriors:
        carving_started = time.perf_counter()
        views = surface_views(scene.frames, perception.objects, motions, config.carving)
        posteriors = carve_posteriors(posteriors, views)
        timing["carving"] = time.perf_counter() - carving_started
    timing["total"] = time.perf_counter() - started
    return PipelineResult(method, posteriors, perception, timing, summary)


def infer(
    scene_path: Path | str,
    out_dir: Path | str,
    *,
    method: str = DEFAULT_METHOD,
    seed: int = 0,
    time_budget_s: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
    config: Config | None = None,
    overwrite: bool = False,
) -> Path:
    """Load a scene, run the pipeline and write the result directory (atomically), with
    ``completion.png``: frame 0's RGB beside the completed objects seen from its camera."""
    from ipr.collision_checker import write_posterior_result
    from ipr.report import completion_png

    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise IprError(
            f"{out_dir}: already exists (fix: choose another folder or pass --overwrite)"
        )
    scene = load_scene(scene_path)
    result = run_pipeline(
        scene,
        config,
        method=method,
        seed=seed,
        time_budget_s=time_budget_s,
        workers=workers,
        samples=samples,
    )
    world_from_camera = {frame.index: frame.world_from_camera for frame in scene.frames}
    extra = {"inference": result.summary} if result.summary else {}
    return write_posterior_result(
        out_dir,
        result.posteriors,
        world_from_camera,
        result.timing_s,
        method=result.method,
        extra=extra,
        extra_files={"completion.png": completion_png(scene.frames[0], result.posteriors)},
        overwrite=overwrite,
    )
