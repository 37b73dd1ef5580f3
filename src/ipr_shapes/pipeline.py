"""The main job: a scene directory in, a result directory out (what ``ipr-shapes infer`` runs).

``run_pipeline(scene, config, method=...)`` is the one entry point the CLI and the Python API
share: perception of every frame, hypotheses for the objects of frame 0 (the initial scene the
result describes), then the chosen inference method: the Collision Checker, or one of the
physics-based methods of ``ipr_shapes.inference`` (default ``ipr+action+uniform``, the full method), or
the paper's Zheng et al. 2013 baseline (``ipr_shapes.baselines``, which makes its own boxes instead of
hypotheses).
The methods that use the pushes' evidence (``+action`` and ``exhaustive``) also register what
the later frames saw of each object into frame 0 (``ipr_shapes.fusion``) before the hypotheses; the
others see frame 0 only, as their likelihood does.

Progress: ``progress`` (``ipr_shapes.progress``) hears of each stage as it advances; nothing is
reported without one. Provenance: ``infer`` records in ``result.json`` (key ``provenance``)
what produced the result, with the whole configuration as ``config.toml`` beside it.

Time budget: ``time_budget_s`` covers the whole run; hypotheses get their share of what is left
after perception and fusion (a per-object timeout), and inference the rest. Without one,
hypotheses have no wall-clock limit (so they do not depend on the machine's load) and sampling
gets ``config.inference.budget_per_object_s`` per object of its own: fusion, hypotheses and the
Collision Checker's starting point come before it and take none of it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import logging
import math
import platform
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ipr_shapes.atomic import check_output_location
from ipr_shapes.baselines import zheng2013
from ipr_shapes.carving import carve_hypotheses, carve_posteriors, surface_views
from ipr_shapes.collision_checker import collision_checker, object_viewpoints
from ipr_shapes.config import Config, config_digest, config_to_toml
from ipr_shapes.errors import IprError
from ipr_shapes.fusion import fuse_views, tracked_free_spaces
from ipr_shapes.hypotheses import Carve, prepare_hypotheses
from ipr_shapes.inference import InferenceOutcome, default_workers, infer_shapes
from ipr_shapes.likelihood import observed_frames
from ipr_shapes.methods import DEFAULT_METHOD, Method, get_method
from ipr_shapes.perception import Perception, check_objects_found, perceive_scene
from ipr_shapes.perception.occlusion import join_first_frame_pieces
from ipr_shapes.perception.outline import hidden_outline_fractions
from ipr_shapes.perception.types import PartialObject
from ipr_shapes.physics import wall_slabs
from ipr_shapes.products import ObjectPosterior, RunSummary, StageTimings
from ipr_shapes.progress import ProgressCallback, report
from ipr_shapes.report import completion_png
from ipr_shapes.report_html import result_label_files, result_labels, write_report_into
from ipr_shapes.result import write_posterior_result
from ipr_shapes.scene import Scene, frames_digest, load_scene

log = logging.getLogger(__name__)

#: The copy of the run's configuration in a result directory.
CONFIG_FILE = "config.toml"


@dataclass(frozen=True, eq=False)
class RunRecord:
    """What a run was given, kept with its result so that ``save_result`` can write it and its
    provenance (``result.json``'s ``provenance``, ``config.toml``).

    Attributes:
        scene: the scene the run perceived.
        config: the configuration as given (None: the defaults).
        seed, time_budget_s, workers, samples: the run's options as asked (None: the default).
    """

    scene: Scene
    config: Config | None
    seed: int
    time_budget_s: float | None
    workers: int | None
    samples: int | None


@dataclass(frozen=True, eq=False)
class PipelineResult:
    """What a run produced.

    Attributes:
        method: the method's name.
        posteriors: per frame-0 object, its shape posterior (in the perception's object order).
        perception: every frame's perception.
        timing: seconds per stage.
        summary: method-specific details (fused views, the sampling summary).
        run: the scene and options it ran with (``save_result`` writes from them).
    """

    method: str
    posteriors: list[ObjectPosterior]
    perception: Perception
    timing: StageTimings
    summary: RunSummary = field(default_factory=RunSummary)
    run: RunRecord | None = None

    @property
    def timing_s(self) -> dict[str, float]:
        """Stage name -> seconds, as ``result.json`` records them."""
        return self.timing.to_dict()


@dataclass(frozen=True)
class RunBudget:
    """The run's time arithmetic (module doc).

    Attributes:
        started: ``time.perf_counter()`` at the start of the run (s).
        deadline: ``time.perf_counter()`` time the whole run must end by (None: no wall-clock
            limit; hypotheses then have no timeout and inference its per-object default).
    """

    started: float
    deadline: float | None

    @classmethod
    def start(cls, time_budget_s: float | None) -> RunBudget:
        """A budget starting now, of ``time_budget_s`` seconds (None: unlimited)."""
        now = time.perf_counter()
        return cls(now, None if time_budget_s is None else now + time_budget_s)

    def remaining_s(self, now: float) -> float | None:
        """Seconds left at ``now`` (at least 1 ms; None without a deadline)."""
        return None if self.deadline is None else max(self.deadline - now, 1e-3)


def _checked_arguments(
    method: str,
    time_budget_s: float | None,
    workers: int | None,
    samples: int | None,
) -> Method:
    """The method; IprError for an unknown method or an out-of-range option."""
    chosen = get_method(method)
    if time_budget_s is not None and not (time_budget_s > 0 and math.isfinite(time_budget_s)):
        raise IprError(f"--time-budget must be positive, got {time_budget_s}")
    if workers is not None and workers < 1:
        raise IprError(f"--workers must be at least 1, got {workers}")
    if samples is not None and samples < 1:
        raise IprError(f"--samples must be at least 1, got {samples}")
    return chosen


#: Seeds are non-negative and fit in 63 bits (numpy's and the workers' seed sequences).
MAX_SEED = 2**63 - 1


def _checked_seed(seed: int) -> int:
    """``seed``; IprError unless it is an integer in 0..MAX_SEED."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise IprError(f"--seed must be a whole number from 0 to 2^63 - 1, got {seed!r}")
    return seed


def perceive(
    scene: Scene,
    config: Config,
    progress: ProgressCallback | None = None,
    workers: int = 1,
) -> Perception:
    """Every frame's perception, with frame 0's occluded pieces joined; ``progress`` hears it
    frame by frame (``perceive_scene``); ``workers`` threads make the frames' partial objects
    and free-space maps (``run_pipeline``: the sampling's, ``_threads``; the result is the same
    for any number)."""
    perception = perceive_scene(scene, config.perception, progress=progress, workers=workers)
    perception, _ = join_first_frame_pieces(scene, perception, config.perception.occluded_pieces)
    mark_kernel_cache_warm()
    return perception


def _kernel_cache_marker() -> Path | None:
    """The file saying that the numba kernels (``ipr_shapes.geometry.kernels``,
    ``ipr_shapes.perception.kernels``, ``ipr_shapes.hypotheses.kernels``,
    ``ipr_shapes.voxel_kernels``, ``ipr_shapes.fusion_kernels``) were compiled into numba's
    cache folder for their present source, this numba and this Python; None when that folder is unknown (e.g. JIT disabled)."""
    try:
        import numba

        from ipr_shapes import fusion_kernels, voxel_kernels
        from ipr_shapes.geometry import kernels as geometry_kernels
        from ipr_shapes.hypotheses import kernels as hypothesis_kernels
        from ipr_shapes.perception import kernels as perception_kernels

        folder = next(
            Path(value._cache._cache_path)
            for value in vars(perception_kernels).values()
            if getattr(getattr(value, "_cache", None), "_cache_path", None)
        )
        digest = hashlib.sha256(f"{numba.__version__} {sys.version}".encode())
        modules = (
            geometry_kernels,
            perception_kernels,
            hypothesis_kernels,
            voxel_kernels,
            fusion_kernels,
        )
        for module in modules:
            digest.update(Path(module.__file__).read_bytes())
        return folder / f"ipr-kernels-{digest.hexdigest()[:16]}.compiled"
    except Exception:  # numba's internals moved, or no cache: say nothing rather than fail
        return None


def kernel_cache_cold() -> bool:
    """Whether the next run will compile the numba kernels first (tens of seconds, once after
    installing or changing them): no perception has finished since their source, numba or
    Python changed, or their cache folder was cleared. One file test."""
    marker = _kernel_cache_marker()
    return marker is not None and not marker.exists()


def mark_kernel_cache_warm() -> None:
    """Record that the kernels are compiled and cached (after a perception finished)."""
    marker = _kernel_cache_marker()
    if marker is not None and not marker.exists():
        with contextlib.suppress(OSError):  # read-only: the next run announces again
            marker.write_text("ipr: the numba kernels in this folder are compiled\n")


@dataclass(frozen=True, eq=False)
class FusedObjects:
    """Frame 0's objects after view fusion (or as perceived, for methods that do not fuse).

    Attributes:
        objects: the partial objects hypotheses are made for.
        object_spaces: per object id, the seen-free space through its registered motion.
        motions: per object id, its registered later-frame motions (for carving).
        fused_views: per result object id, the later frames fused into it; None
            when the method does not fuse.
    """

    objects: tuple[PartialObject, ...]
    object_spaces: Mapping = field(default_factory=dict)
    motions: Mapping = field(default_factory=dict)
    fused_views: Mapping[str, list[int]] | None = None


def _threads(config: Config, workers: int | None) -> int:
    """Threads of fusion: the sampling's (``--workers``, else ``inference.workers``, else all
    cores); its result is the same for any number."""
    return workers or config.inference.workers or default_workers()


def fuse(
    scene: Scene,
    perception: Perception,
    method: Method,
    config: Config,
    workers: int | None = None,
) -> FusedObjects:
    """Register the later frames' views into frame 0 for the methods that use the pushes;
    ``workers`` threads share the registrations' k-d tree queries (None: the sampling's, as
    ``ipr_shapes.inference.infer_shapes`` chooses them; the result is the same for any)."""
    objects = perception.objects[0]
    if not (method.actions and config.fusion.enabled):
        return FusedObjects(objects)
    support = next((p for p in perception.planes[0] if p.kind == "support"), None)
    fused = fuse_views(
        perception.objects,
        perception.free_space,
        support,
        config.fusion,
        _threads(config, workers),
    )
    object_spaces: dict = {}
    if config.fusion.later_free_space or config.fusion.pusher_free_space:
        object_spaces = tracked_free_spaces(
            fused, perception.free_space, scene.pushes, scene.pusher, config.fusion
        )
    # Keyed by the result's object ids (the perception's), listing the later frames fused.
    fused_views = {
        str(obj.id): fused.fused_frames[obj.id]
        for obj in fused.objects
        if obj.id in fused.fused_frames
    }
    return FusedObjects(fused.objects, object_spaces, fused.motions, fused_views)


def checker_hidden_fractions(
    scene: Scene, perception: Perception, config: Config
) -> dict[int, float] | None:
    """Each frame-0 object's hidden outline fraction (``perception.outline``), which the
    Collision Checker's medoid weights read when they are "outline" or "outline-fit"; None for
    weights that do not read it."""
    if config.collision_checker.medoid_weights not in ("outline", "outline-fit"):
        return None
    return hidden_outline_fractions(
        scene.frames[0].depth_m,
        perception.objects[0],
        config.perception.segmentation.contour_gap_m,
    )


def infer_with_physics(
    scene: Scene,
    perception: Perception,
    fused: FusedObjects,
    method: Method,
    config: Config,
    rng: np.random.Generator,
    remaining_s: float | None,
    deadline: float | None,
    *,
    seed: int,
    workers: int | None,
    progress: ProgressCallback | None = None,
    carve: Carve | None = None,
) -> tuple[InferenceOutcome, float]:
    """Hypotheses with their constraints, then a physics-based method's posteriors; also the
    seconds the hypotheses took. ``remaining_s``: the run's time left (hypotheses take their
    share); ``deadline``: ``time.perf_counter()`` time inference stops at (None: its default
    budget); ``carve``: the candidates are carved by it before the choice
    (``CarvingConfig.before_choice``; None: not)."""
    started = time.perf_counter()
    prepared = prepare_hypotheses(
        fused.objects,
        perception.free_space[0],
        perception.planes[0],
        config.hypotheses,
        config.constraints,
        rng,
        remaining_s,
        fused.object_spaces,
        progress,
        carve,
    )
    hypotheses_s = time.perf_counter() - started
    observed = observed_frames(
        scene.frames, perception.labels, config.inference.likelihood.decimation
    )
    # The Collision Checker's medoid weights as the physics medoid's base measure
    # (``InferenceConfig.medoid_base``) read the frame-0 outline and the objects' points.
    judged = config.inference.medoid_base == "collision-checker"
    hidden = checker_hidden_fractions(scene, perception, config) if judged else None
    camera = np.asarray(scene.frames[0].world_from_camera, float)[:3, 3]
    try:
        outcome = infer_shapes(
            prepared,
            perception.planes[0],
            observed,
            method=method.name,
            pusher=scene.pusher,
            pushes=scene.pushes,
            config=config.inference,
            collision_checker_config=config.collision_checker,
            seed=seed,
            deadline=deadline,
            workers=workers,
            progress=progress,
            points={o.id: o.points for o in fused.objects}
            if config.inference.surface_fit or judged
            else None,
            hidden=hidden,
            viewpoints={o.id: object_viewpoints(o, camera) for o in fused.objects}
            if judged
            else None,
        )
    except IprError as error:  # say which scene the method refused
        raise IprError(f"{scene.path}: {error}") from None
    return outcome, hypotheses_s


def run_pipeline(
    scene: Scene,
    config: Config | None = None,
    *,
    method: str = DEFAULT_METHOD,
    seed: int = 0,
    time_budget_s: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
    progress: ProgressCallback | None = None,
) -> PipelineResult:
    """Perceive the scene and infer complete shapes of the objects of frame 0.

    ``samples`` fixes the number of joint models the physics-based methods sample (then only
    ``time_budget_s``, if given, can stop them earlier): the same seed and samples give the
    same result with any number of ``workers`` (sampling threads of this process).

    ``progress``: an observer of the run's stages (``ipr_shapes.progress``; None: nothing reported).
    """
    chosen = _checked_arguments(method, time_budget_s, workers, samples)
    _checked_seed(seed)
    record = RunRecord(scene, config, seed, time_budget_s, workers, samples)
    config = config or Config()
    if samples is not None:
        config = dataclasses.replace(
            config, inference=dataclasses.replace(config.inference, max_samples=samples)
        )
    budget = RunBudget.start(time_budget_s)
    if progress is not None and kernel_cache_cold():
        report(progress, "compiling", 0)
    perception = perceive(scene, config, progress, workers=_threads(config, workers))
    perceived = time.perf_counter()
    check_objects_found(scene, perception)
    if not perception.objects[0]:
        log.warning(
            "%s: no object found in frame %d; the result is empty",
            scene.path,
            scene.frames[0].index,
        )
    if chosen.actions and config.fusion.enabled:
        report(progress, "fusion", 0, 1)
    fused = fuse(scene, perception, chosen, config, workers)
    if chosen.actions and config.fusion.enabled:
        report(progress, "fusion", 1, 1)
    fused_at = time.perf_counter()
    remaining = budget.remaining_s(fused_at)
    rng = np.random.default_rng(seed)
    # The views that carve the written shapes; with ``before_choice`` they carve the candidates
    # before inference chooses among them too (``ipr_shapes.carving``).
    views = carve = None
    if config.carving.enabled and config.carving.before_choice:
        views = surface_views(scene.frames, perception.objects, fused.motions, config.carving)
        carve = functools.partial(carve_hypotheses, views=views)
    summary = RunSummary(fused_views=fused.fused_views)
    if chosen.name == "zheng2013":
        outcome = zheng2013(
            fused.objects,
            perception.free_space[0],
            perception.planes[0],
            config.zheng2013,
            camera_m=np.asarray(scene.frames[0].world_from_camera, float)[:3, 3],
        )
        posteriors = outcome.posteriors
        timing = StageTimings(
            segmentation=perceived - budget.started,
            hypotheses=float(sum(p.generation_s for p in posteriors)),
            inference=max(
                time.perf_counter() - perceived - sum(p.generation_s for p in posteriors), 0.0
            ),
        )
    elif not chosen.physics:
        posteriors = collision_checker(
            fused.objects,
            perception.free_space[0],
            perception.planes[0],
            config.collision_checker,
            rng=rng,
            time_budget_s=remaining,
            object_spaces=fused.object_spaces,
            hypotheses=config.hypotheses,
            constraints=config.constraints,
            progress=progress,
            hidden=checker_hidden_fractions(scene, perception, config),
            camera_m=np.asarray(scene.frames[0].world_from_camera, float)[:3, 3],
            carve=carve,
        )
        generation = float(sum(p.generation_s for p in posteriors))
        timing = StageTimings(
            segmentation=perceived - budget.started,
            fusion=fused_at - perceived if fused.fused_views is not None else None,
            hypotheses=generation,
            inference=max(time.perf_counter() - fused_at - generation, 0.0),
        )
    else:
        outcome, hypotheses_s = infer_with_physics(
            scene, perception, fused, chosen, config, rng, remaining, budget.deadline,
            seed=seed, workers=workers, progress=progress, carve=carve,
        )  # fmt: skip
        posteriors = outcome.posteriors
        summary = dataclasses.replace(summary, sampling=outcome.summary)
        timing = StageTimings(
            segmentation=perceived - budget.started,
            fusion=fused_at - perceived,
            hypotheses=hypotheses_s,
            inference=time.perf_counter() - fused_at - hypotheses_s,
            inference_collision_checker=outcome.timing_s["collision_checker"],
            inference_sampling=outcome.timing_s["sampling"],
        )
    if config.carving.enabled and posteriors:
        report(progress, "carving", 0, 1)
        carving_started = time.perf_counter()
        if views is None:
            views = surface_views(scene.frames, perception.objects, fused.motions, config.carving)
        posteriors = carve_posteriors(posteriors, views)
        timing = dataclasses.replace(timing, carving=time.perf_counter() - carving_started)
        report(progress, "carving", 1, 1)
    timing = dataclasses.replace(timing, total=time.perf_counter() - budget.started)
    return PipelineResult(chosen.name, posteriors, perception, timing, summary, record)


def infer(
    scene_path: Path | str | Scene,
    out_dir: Path | str,
    *,
    method: str = DEFAULT_METHOD,
    seed: int = 0,
    time_budget_s: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
    progress: ProgressCallback | None = None,
    config: Config | None = None,
    overwrite: bool = False,
    up_camera: Sequence[float] | None = None,
    frames: Sequence[int] | None = None,
) -> Path:
    """Load a scene (or take a loaded one, e.g. from ``ipr_shapes.from_arrays``), run the pipeline and
    write the result directory (``save_result``); the result's folder. ``up_camera``: the up
    direction in camera coordinates for a scene folder without camera poses
    (``ipr_shapes.scene.load_scene``); ``frames``: the frame ids to use (None: all)."""
    out_dir = check_output_location(out_dir, _input_paths(scene_path), overwrite=overwrite)
    result = infer_scene(
        scene_path,
        method=method,
        seed=seed,
        time_budget_s=time_budget_s,
        workers=workers,
        samples=samples,
        progress=progress,
        config=config,
        up_camera=up_camera,
        frames=frames,
    )
    return save_result(result, out_dir, overwrite=overwrite)


def _input_paths(scene: Scene | Path | str) -> list[Path | str]:
    """The folders an output must not replace: the scene's, when it has one on disk (a scene
    from arrays has none)."""
    if isinstance(scene, Scene):
        return [scene.path] if Path(scene.path).exists() else []
    return [scene]


def infer_scene(
    scene: Scene | Path | str,
    out_dir: Path | str | None = None,
    *,
    method: str = DEFAULT_METHOD,
    seed: int = 0,
    time_budget_s: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
    progress: ProgressCallback | None = None,
    config: Config | None = None,
    overwrite: bool = False,
    up_camera: Sequence[float] | None = None,
    frames: Sequence[int] | None = None,
) -> PipelineResult:
    """``ipr_shapes.infer``: the pipeline on a scene folder or a ``Scene`` (``load_scene``,
    ``ipr_shapes.from_arrays``); writes the result directory too when ``out_dir`` is given (checked
    before the run). The options are ``run_pipeline``'s; ``up_camera`` is ``load_scene``'s and
    applies to a folder only, and so does ``frames`` (the frame ids to use; None: all)."""
    _checked_seed(seed)
    if out_dir is not None:
        out_dir = check_output_location(out_dir, _input_paths(scene), overwrite=overwrite)
    if not isinstance(scene, Scene):
        scene = load_scene(scene, up_camera=up_camera, frames=frames)
    elif up_camera is not None or frames is not None:
        raise IprError(
            "up_camera and frames apply to a scene folder; a Scene already has its world frame "
            "and frames (fix: give them to ipr_shapes.from_arrays or load_scene instead)"
        )
    result = run_pipeline(
        scene,
        config,
        method=method,
        seed=seed,
        time_budget_s=time_budget_s,
        workers=workers,
        samples=samples,
        progress=progress,
    )
    if out_dir is not None:
        save_result(result, out_dir, overwrite=overwrite)
    return result


def save_result(result: PipelineResult, out_dir: Path | str, *, overwrite: bool = False) -> Path:
    """Write a run's result directory atomically (docs/FORMATS.md): ``result.json`` with its
    provenance, the meshes, ``occupancy.npz``, ``config.toml``, ``completion.png`` (frame 0's
    RGB beside the completed objects seen from its camera), ``labels/`` (each frame's
    segmentation with the result's object ids) and ``report.html`` (``ipr_shapes.report_html``: the
    page to check the result in a browser); the folder."""
    if result.run is None:
        raise IprError("this result does not record its run (fix: make it with run_pipeline)")
    run = result.run
    scene = run.scene
    world_from_camera = {frame.index: frame.world_from_camera for frame in scene.frames}
    details = result.summary.to_dict()
    extra = {"inference": details} if details else {}
    # What produced it (module doc): the provenance, and the whole configuration beside it.
    config = run.config or Config()
    extra["provenance"] = run_provenance(
        scene, config, method=result.method, seed=run.seed,
        time_budget_s=run.time_budget_s, workers=run.workers, samples=run.samples,
    )  # fmt: skip
    # The walls as the physics simulated them, for exports (docs/FORMATS.md, "walls").
    extra["walls"] = [
        {"vertices_m": np.round(slab, 6).tolist()}
        for slab in wall_slabs(result.perception.planes[0], config.inference.physics)
    ] if result.perception.planes else []  # fmt: skip
    # The segmentation with the result's ids, and report.html made from the written result
    # before it is renamed into place (one atomic step with the rest).
    labels = result_labels(
        result.perception.labels,
        result.perception.objects[0] if result.perception.objects else (),
        [posterior.object_id for posterior in result.posteriors],
    )
    return write_posterior_result(
        out_dir,
        result.posteriors,
        world_from_camera,
        result.timing_s,
        method=result.method,
        extra=extra,
        extra_files={
            "completion.png": completion_png(scene.frames[0], result.posteriors),
            CONFIG_FILE: config_to_toml(config).encode(),
            **result_label_files(labels, scene.frames),
        },
        overwrite=overwrite,
        finish=lambda staging: write_report_into(staging, scene),
    )


def run_provenance(
    scene: Scene,
    config: Config,
    *,
    method: str,
    seed: int,
    time_budget_s: float | None,
    workers: int | None,
    samples: int | None,
) -> dict:
    """What produced a result (``result.json``'s ``provenance``; docs/FORMATS.md): the ipr
    version, method, seed, budget as asked (None: the default), the configuration's digest and
    file, the scene, the frames read and their digest, the main libraries' versions and the
    time."""
    import mujoco

    import ipr_shapes

    return {
        "ipr_version": ipr_shapes.__version__,
        "distribution": ipr_shapes.DISTRIBUTION,
        "method": method,
        "seed": int(seed),
        "budget": {
            "time_budget_s": None if time_budget_s is None else float(time_budget_s),
            "samples": samples,
            "workers": workers,
        },
        "config_digest": config_digest(config),
        "config_file": CONFIG_FILE,
        # A scene from arrays (ipr_shapes.from_arrays) has a name, not a folder.
        "scene": str(Path(scene.path).resolve() if Path(scene.path).exists() else scene.path),
        "frames": [int(frame.index) for frame in scene.frames],
        "frames_digest": frames_digest(scene.frames),
        "software": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "mujoco": mujoco.__version__,
        },
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }
