"""Many scenes in one call (``ipr-shapes batch``): one result folder per scene, a summary table, and
``ipr-shapes eval`` scores where the scene has ground truth.

- Scenes: scene folders (holding ``scene_camera.json``), folders of scene folders (a suite, a
  BOP split) or glob patterns; each result goes to ``OUT/<scene folder name>``.
- Resumable: a scene whose result folder already holds a valid result is kept, not rerun; a
  scene that fails is reported in the summary and does not stop the others.
- Parallel: scenes run in a local process pool (one process per core by default), each with one
  sampling worker, since a pool of pools would oversubscribe the cores.
- Summary: ``OUT/summary.json`` (every scene's status, objects, seconds, scores, error) and
  ``OUT/summary.md`` (the same as a table), rewritten atomically after every scene so that an
  interrupted batch still says what it finished.
"""

from __future__ import annotations

import contextlib
import glob
import math
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from ipr_shapes.atomic import check_output_location, write_json, write_text
from ipr_shapes.config import Config
from ipr_shapes.errors import IprError
from ipr_shapes.methods import DEFAULT_METHOD, get_method
from ipr_shapes.workers import quiet_worker

SUMMARY_JSON = "summary.json"
SUMMARY_MD = "summary.md"


@dataclass(frozen=True)
class BatchOptions:
    """How every scene of a batch is run (``ipr_shapes.pipeline.infer``'s options).

    Attributes:
        method: inference method (``ipr_shapes.methods``).
        seed: seed of every scene's run.
        time_budget_s: wall-clock budget per scene (s; None: the method's default).
        samples: joint models sampled per scene (None: as the budget allows).
        config: the run's configuration (None: the defaults).
        evaluate: score each result against the scene's ground truth when it has some.
        up_camera: the up direction in camera coordinates for scenes without camera poses
            (``ipr_shapes.scene.load_scene``; None: from the data).
        frames: the frame ids every scene uses (``ipr_shapes.scene.load_scene``; None: all), e.g.
            the first few of BOP scenes with hundreds of frames.
    """

    method: str = DEFAULT_METHOD
    seed: int = 0
    time_budget_s: float | None = None
    samples: int | None = None
    config: Config | None = None
    evaluate: bool = True
    up_camera: tuple[float, float, float] | None = None
    frames: tuple[int, ...] | None = None


@dataclass(frozen=True)
class SceneOutcome:
    """One scene's line of the summary.

    Attributes:
        scene: the scene folder.
        result: its result folder.
        status: "done" (run now), "kept" (a valid result was already there) or "failed".
        objects: objects in the result (None when failed).
        seconds: wall time of the run (0 when kept).
        object_iou, scene_iou: ``ipr-shapes eval`` IoUs when the scene has ground truth, else None.
        error: the one-line error of a failed scene.
    """

    scene: str
    result: str
    status: str
    objects: int | None = None
    seconds: float = 0.0
    object_iou: float | None = None
    scene_iou: float | None = None
    error: str | None = None


@dataclass(frozen=True)
class BatchSummary:
    """Every scene's outcome, in the order the scenes were given."""

    out_dir: str
    method: str
    outcomes: tuple[SceneOutcome, ...] = field(default_factory=tuple)

    @property
    def failed(self) -> int:
        """Scenes that failed."""
        return sum(o.status == "failed" for o in self.outcomes)


def is_scene(folder: Path) -> bool:
    """A BOP scene folder: it holds ``scene_camera.json``."""
    return (folder / "scene_camera.json").is_file()


def find_scenes(patterns: Iterable[str | Path]) -> list[Path]:
    """The scene folders named by ``patterns`` (scene folders, folders of scene folders or
    globs), in order, each once; IprError naming the pattern that matches none."""
    scenes: list[Path] = []
    for pattern in patterns:
        text = str(pattern)
        matches = (
            [Path(p) for p in sorted(glob.glob(text))] if glob.has_magic(text) else [Path(text)]
        )
        found = []
        for match in matches:
            if is_scene(match):
                found.append(match)
            elif match.is_dir():
                found += sorted(p for p in match.iterdir() if p.is_dir() and is_scene(p))
        if not found:
            raise IprError(
                f"{text}: no scene folder (one holding scene_camera.json) there "
                "(fix: name scene folders, folders of scenes or a glob of them)"
            )
        scenes += [s for s in found if s.resolve() not in {x.resolve() for x in scenes}]
    names = [s.name for s in scenes]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise IprError(
            f"scenes with the same folder name {clash} would share a result folder "
            "(fix: run them in separate batches)"
        )
    return scenes


def _kept(result_dir: Path) -> int | None:
    """Objects of a valid result already in ``result_dir``, else None."""
    from ipr_shapes.result import load_result

    if not (result_dir / "result.json").is_file():
        return None
    try:
        return len(load_result(result_dir, load_meshes=False).objects)
    except IprError:
        return None


def _scores(scene: Path, result_dir: Path) -> tuple[float | None, float | None]:
    """(object IoU, scene IoU) of ``ipr-shapes eval``, or Nones when the scene has no ground truth."""
    from ipr_shapes.metrics import evaluate

    if not (scene / "scene_gt.json").is_file():
        return None, None
    evaluation = evaluate(scene, result_dir)
    return evaluation.object_space.iou, evaluation.scene_space.iou


def run_scene(scene: Path, result_dir: Path, options: BatchOptions) -> SceneOutcome:
    """Run (or keep) one scene; never raises: a failure is the outcome's ``error``."""
    from ipr_shapes.pipeline import infer

    base = {"scene": str(scene), "result": str(result_dir)}
    kept = _kept(result_dir)
    started = time.perf_counter()
    try:
        if kept is None:
            infer(
                scene,
                result_dir,
                method=options.method,
                seed=options.seed,
                time_budget_s=options.time_budget_s,
                workers=1,
                samples=options.samples,
                config=options.config,
                overwrite=result_dir.exists(),
                up_camera=options.up_camera,
                frames=options.frames,
            )
            objects = _kept(result_dir)
            status, seconds = "done", time.perf_counter() - started
        else:
            objects, status, seconds = kept, "kept", 0.0
        object_iou = scene_iou = None
        if options.evaluate:
            object_iou, scene_iou = _scores(scene, result_dir)
    except (IprError, OSError, ValueError) as error:
        return SceneOutcome(**base, status="failed", error=" ".join(str(error).split()))
    except Exception as error:  # noqa: BLE001 - one scene's crash must not stop the batch
        last = traceback.format_exception_only(type(error), error)[-1].strip()
        return SceneOutcome(**base, status="failed", error=f"crashed: {last}")
    return SceneOutcome(**base, status=status, objects=objects, seconds=seconds,
                        object_iou=object_iou, scene_iou=scene_iou)  # fmt: skip


def _summary_markdown(summary: BatchSummary) -> str:
    def number(value: float | None, digits: int = 3) -> str:
        return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"

    lines = [
        f"# ipr-shapes batch: {summary.method}",
        "",
        "| scene | status | objects | seconds | object IoU | scene IoU | error |",
        "|---|---|---|---|---|---|---|",
    ]
    for o in summary.outcomes:
        lines.append(
            f"| {Path(o.scene).name} | {o.status} | {'-' if o.objects is None else o.objects} "
            f"| {number(o.seconds, 1)} | {number(o.object_iou)} | {number(o.scene_iou)} "
            f"| {(o.error or '').replace('|', '/')} |"
        )
    scored = [o for o in summary.outcomes if o.object_iou is not None]
    if scored:
        mean = sum(o.object_iou for o in scored) / len(scored)
        lines += ["", f"Mean object IoU over {len(scored)} scored scenes: {mean:.3f}"]
    return "\n".join(lines) + "\n"


def _write_summary(summary: BatchSummary) -> None:
    out = Path(summary.out_dir)
    write_json(out / SUMMARY_JSON, asdict(summary))
    write_text(out / SUMMARY_MD, _summary_markdown(summary))


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text if len(text) <= 300 else text[:297] + "..."


def run_scene_detached(scene: str, options: BatchOptions) -> tuple[SceneOutcome, dict[str, bytes]]:
    """Run one scene on a machine that does not share the batch's output folder (a Ray worker):
    into a temporary folder here, returned as its files (path relative to the result folder ->
    bytes) for the caller to write. The scene must be readable here at the same path. Never
    raises; the outcome's ``result`` is the temporary folder (gone on return)."""
    import socket
    import tempfile

    folder = Path(scene)
    if not folder.is_dir():
        outcome = SceneOutcome(str(folder), "", "failed", error=(
            f"{folder}: not found on the cluster node {socket.gethostname()} (fix: put the "
            "scenes on a filesystem every node mounts at the same path)"))  # fmt: skip
        return outcome, {}
    with tempfile.TemporaryDirectory(prefix="ipr-batch-") as temporary:
        result_dir = Path(temporary) / folder.name
        outcome = run_scene(folder, result_dir, options)
        files = {}
        if outcome.status != "failed":
            files = {
                path.relative_to(result_dir).as_posix(): path.read_bytes()
                for path in sorted(result_dir.rglob("*"))
                if path.is_file()
            }
    return outcome, files


def write_result_files(files: dict[str, bytes], result_dir: Path) -> None:
    """Write a detached run's files as ``result_dir`` in one atomic step (replacing what is
    there); IprError if a path would leave the folder."""
    from ipr_shapes.atomic import staged_directory

    with staged_directory(result_dir) as staging:
        for name, content in files.items():
            relative = Path(name)
            if relative.is_absolute() or ".." in relative.parts or not relative.parts:
                raise IprError(f"{result_dir}: a result file path {name!r} leaves the folder")
            target = staging / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(content)


@dataclass(frozen=True)
class _Runner:
    """Where scenes run: ``submit(scene, result_dir)`` starts one and returns a future;
    ``settle(value, scene, result_dir)`` turns the future's value into the scene's outcome
    (writing what must be written here); ``window`` caps the scenes in flight (None: all)."""

    submit: Callable[[Path, Path], Future]
    settle: Callable[[object, Path, Path], SceneOutcome]
    window: int | None = None


def _run_all(
    scenes: Sequence[Path],
    out: Path,
    runner: _Runner,
    finish: Callable[[int, SceneOutcome], None],
    indices: Iterable[int],
    idle: Callable[[], None] | None = None,
) -> None:
    """Run the scenes at ``indices`` through ``runner``, calling ``finish`` as each ends; a
    scene whose worker is lost (a crash, a lost node) is a failed outcome, not an exception.
    ``idle`` runs once, after the first submissions (work for this process meanwhile)."""
    queue = list(indices)
    futures: dict[Future, int] = {}
    window = runner.window or max(1, len(queue))

    def top_up() -> None:
        while queue and len(futures) < window:
            index = queue.pop(0)
            scene = scenes[index]
            futures[runner.submit(scene, out / scene.name)] = index

    top_up()
    if idle is not None:
        idle()
    while futures:
        finished, _ = wait(set(futures), return_when=FIRST_COMPLETED)
        for future in sorted(finished, key=futures.get):
            index = futures.pop(future)
            scene = scenes[index]
            try:
                outcome = runner.settle(future.result(), scene, out / scene.name)
            except Exception as error:  # noqa: BLE001 - a worker died or a node was lost
                outcome = SceneOutcome(str(scene), str(out / scene.name), "failed",
                                       error=f"worker died: {_one_line(error)}")  # fmt: skip
            finish(index, outcome)
        top_up()


def _settle_local(value: object, scene: Path, result_dir: Path) -> SceneOutcome:
    assert isinstance(value, SceneOutcome)
    return value


def _settle_detached(value: object, scene: Path, result_dir: Path) -> SceneOutcome:
    """Write a detached run's result folder here (atomically) and point its outcome at it."""
    outcome, files = value  # type: ignore[misc]
    outcome = replace(outcome, scene=str(scene), result=str(result_dir))
    if outcome.status == "failed":
        return outcome
    try:
        write_result_files(files, result_dir)
    except (IprError, OSError) as error:
        return replace(outcome, status="failed", objects=None, object_iou=None, scene_iou=None,
                       error=f"result not written: {_one_line(error)}")  # fmt: skip
    return outcome


def run_batch(
    scenes: Sequence[Path],
    out_dir: Path | str,
    options: BatchOptions | None = None,
    *,
    jobs: int | None = None,
    ray_address: str | None = None,
    on_outcome: Callable[[SceneOutcome], None] | None = None,
) -> BatchSummary:
    """Run every scene into ``out_dir/<scene name>``, keeping valid results already there: with
    ``jobs`` local processes (default: the cores this process may use; 1: in this process), or
    on the Ray cluster at ``ray_address`` (``ipr_shapes.cluster``; ``jobs``: at most that many scenes
    at once, default all).

    On Ray every worker runs its scene into a folder of its own and returns the files, which
    this process writes atomically, so the output folder need not be shared; the scenes must be
    readable on every node at the same path. Kept results are scored here.

    ``on_outcome`` is called with each scene's outcome as it finishes (progress). The summary
    files are rewritten after every scene. Raises IprError before any work (nothing written)
    when the output folder would overlap a scene, or the Ray cluster cannot be used."""
    options = options or BatchOptions()
    get_method(options.method)
    out = Path(out_dir)
    scenes = [Path(s) for s in scenes]
    for scene in scenes:  # OUT, and every result folder, must stay clear of every scene
        check_output_location(out, [scene], overwrite=True)
    with contextlib.ExitStack() as stack:
        ray = None
        if ray_address is not None:
            from ipr_shapes.cluster import connect

            ray = stack.enter_context(connect(ray_address))
        out.mkdir(parents=True, exist_ok=True)
        if jobs is None and ray is None:
            jobs = max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
        outcomes: dict[int, SceneOutcome] = {}

        def finish(index: int, outcome: SceneOutcome) -> None:
            outcomes[index] = outcome
            done = tuple(outcomes[i] for i in sorted(outcomes))
            _write_summary(BatchSummary(str(out), options.method, done))
            if on_outcome is not None:
                on_outcome(outcome)

        if ray is not None:
            remote = ray.remote(num_cpus=1, max_retries=1)(run_scene_detached)
            kept = [i for i, scene in enumerate(scenes) if _kept(out / scene.name) is not None]

            def score_kept() -> None:  # here, while the cluster runs the others
                for index in kept:
                    finish(index, run_scene(scenes[index], out / scenes[index].name, options))

            runner = _Runner(
                submit=lambda scene, _: remote.remote(str(scene.absolute()), options).future(),
                settle=_settle_detached,
                window=jobs,
            )
            rest = [i for i in range(len(scenes)) if i not in set(kept)]
            _run_all(scenes, out, runner, finish, rest, idle=score_kept)
        elif jobs <= 1 or len(scenes) <= 1:
            for index, scene in enumerate(scenes):
                finish(index, run_scene(scene, out / scene.name, options))
        else:
            # "spawn": each worker is this process's own child, so the kernel ends it when this
            # process dies (``quiet_worker``); a forkserver's children outlive a killed parent.
            context = multiprocessing.get_context("spawn")
            pool = stack.enter_context(
                ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=quiet_worker)
            )
            runner = _Runner(
                submit=lambda scene, result_dir: pool.submit(run_scene, scene, result_dir, options),
                settle=_settle_local,
            )
            _run_all(scenes, out, runner, finish, range(len(scenes)))
    return BatchSummary(str(out), options.method, tuple(outcomes[i] for i in sorted(outcomes)))
