"""The ``ipr`` command: one sub-command per job.

Outside tools call these exactly so (the scene contract's interface):

    ipr-shapes synth OUT_DIR --kind {static,dynamic} --seed S --count N
    ipr-shapes eval SCENE RESULT [--models DIR] [--json FILE]

Errors in the input are reported as one line naming the file, the problem and the fix, with a
non-zero exit status and no traceback (``-v`` shows logs, ``-vv`` also tracebacks).
"""

from __future__ import annotations

import argparse
import errno
import functools
import logging
import sys
import time
from pathlib import Path

from ipr_shapes.atomic import write_json
from ipr_shapes.errors import IprError
from ipr_shapes.methods import DEFAULT_METHOD, METHODS

log = logging.getLogger("ipr_shapes")

EXIT_INPUT_ERROR = 2
#: Errors of writing the output that are reported in one line, not as a traceback.
_WRITE_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG}
)


def _progress(console=None):
    """A rich progress bar on stderr (or ``console``), disabled when it is not a terminal."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    console = console or Console(stderr=True)
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        _time_left_column(),
        console=console,
        disable=not console.is_terminal,
    )


def _time_left_column():
    """A column counting down to a task's ``deadline`` field (``time.monotonic()``), if any."""
    from rich.progress import ProgressColumn
    from rich.text import Text

    class TimeLeft(ProgressColumn):
        def render(self, task) -> Text:
            deadline = task.fields.get("deadline")
            if deadline is None or task.finished:
                return Text("")
            return Text(f"{max(deadline - time.monotonic(), 0.0):.0f} s left", style="cyan")

    return TimeLeft()


#: Shown once when the numba kernels are about to be compiled (``ipr_shapes.progress``, "compiling").
COMPILING_NOTICE = "ipr-shapes: compiling the perception kernels once (about 30 s)..."
_STAGE_LABELS = {
    "perception": "perception (frames)",
    "free_space": "free space (frames)",
    "fusion": "fusion of later views",
    "hypotheses": "hypotheses (objects)",
    "sampling": "sampling (joint models)",
    "carving": "carving",
}


class _ProgressBars:
    """Draws a run's ``ipr_shapes.progress`` events as one rich progress bar per stage."""

    def __init__(self, progress) -> None:
        self._progress = progress
        self._tasks: dict[str, int] = {}

    def __call__(self, event) -> None:
        if event.stage == "compiling":  # _with_progress has announced it
            return
        left = event.seconds_left
        deadline = None if left is None else time.monotonic() + left
        task = self._tasks.get(event.stage)
        if task is None:
            self._tasks[event.stage] = self._progress.add_task(
                _STAGE_LABELS.get(event.stage, event.stage),
                total=event.total,
                completed=event.done,
                deadline=deadline,
            )
        else:
            self._progress.update(task, total=event.total, completed=event.done, deadline=deadline)


def _with_progress(label: str | None = None):
    """Run a command with progress on stderr when it is a terminal (nothing otherwise): a
    notice when the numba kernels are about to be compiled, ``args.progress`` (the observer
    ``ipr_shapes.pipeline`` reports to, or None) and, with ``label``, a bar for the whole command."""

    def decorate(handler):
        @functools.wraps(handler)
        def run(args: argparse.Namespace) -> int:
            from ipr_shapes.pipeline import kernel_cache_cold, mark_kernel_cache_warm

            with _progress() as progress:
                args.progress = None if progress.disable else _ProgressBars(progress)
                if args.progress is not None and kernel_cache_cold():
                    progress.console.print(COMPILING_NOTICE, highlight=False)
                task = progress.add_task(label, total=None) if args.progress and label else None
                status = handler(args)
                if task is not None:
                    progress.update(task, total=1, completed=1)
            mark_kernel_cache_warm()  # a perception finished: the kernels are in the cache
            return status

        return run

    return decorate


class _VersionAction(argparse.Action):
    """``--version``: print the version and the distribution's name, and exit 0."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs) -> None:
        kwargs.setdefault("help", "print the version and exit")
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        import ipr_shapes

        print(f"ipr-shapes {ipr_shapes.__version__} (distribution {ipr_shapes.DISTRIBUTION})")
        parser.exit(0)


def _cmd_synth(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ipr_shapes.synth import SynthConfig, generate_scenes

    started = time.perf_counter()
    try:
        config = SynthConfig()
        if args.width is not None:
            config = replace(config, width=args.width)
        if args.height is not None:
            config = replace(config, height=args.height)
        with _progress() as progress:
            task = progress.add_task(f"synth {args.kind}", total=args.count)
            paths = generate_scenes(
                Path(args.out_dir),
                kind=args.kind,
                seed=args.seed,
                count=args.count,
                config=config,
                models_dir=Path(args.models) if args.models else None,
                overwrite=args.overwrite,
                progress=lambda done, total: progress.update(task, completed=done),
            )
    except ValueError as error:  # invalid arguments, reported like any input error
        raise IprError(str(error)) from error
    elapsed = time.perf_counter() - started
    for path in paths:
        print(path)
    log.info("generated %d scenes in %.1f s", len(paths), elapsed)
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    from ipr_shapes.metrics import evaluate, format_table

    evaluation = evaluate(
        Path(args.scene), Path(args.result), models_dir=Path(args.models) if args.models else None
    )
    print(format_table(evaluation))
    if args.json:
        write_json(Path(args.json), evaluation.to_dict())
    return 0


def _cmd_ground_truth(args: argparse.Namespace) -> int:
    from ipr_shapes.ground_truth import write_ground_truth_result

    path = write_ground_truth_result(
        Path(args.scene),
        Path(args.out),
        models_dir=Path(args.models) if args.models else None,
        overwrite=args.overwrite,
    )
    print(path)
    return 0


def _seed(text: str) -> int:
    """A ``--seed``: a whole number from 0 to 2^63 - 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"must be from 0 to 2^63 - 1, got {value}")
    return value


def _frame_selection(text: str) -> tuple[int, ...]:
    """A ``--frames`` selection (``ipr_shapes.scene.parse_frame_selection``)."""
    from ipr_shapes.scene import parse_frame_selection

    try:
        return parse_frame_selection(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error).removeprefix("--frames: ")) from None


def _add_frames_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--frames",
        type=_frame_selection,
        metavar="IDS",
        help="the frame ids to use (default: all), e.g. 0,5,10 or 0-20:5 (ids 0 to 20 in steps "
        "of 5); the first is the reference frame. Both frames of every push between the "
        "chosen frames must be chosen",
    )


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _config(args: argparse.Namespace):
    """The run's Config: ``--config FILE`` over the defaults (None: the defaults)."""
    if not getattr(args, "config", None):
        return None
    from ipr_shapes.config import read_config

    return read_config(Path(args.config))


@_with_progress()
def _cmd_infer(args: argparse.Namespace) -> int:
    import dataclasses

    from ipr_shapes.config import Config
    from ipr_shapes.pipeline import infer
    from ipr_shapes.result import load_result

    config = _config(args)
    if args.no_carving:
        config = config or Config()
        config = dataclasses.replace(
            config, carving=dataclasses.replace(config.carving, enabled=False)
        )
    out = infer(
        Path(args.scene),
        Path(args.out),
        progress=args.progress,
        method=args.method,
        seed=args.seed,
        time_budget_s=args.time_budget,
        workers=args.workers,
        samples=args.samples,
        config=config,
        overwrite=args.overwrite,
        up_camera=args.up,
        frames=args.frames,
    )
    result = load_result(out, load_meshes=False)
    shown = ("segmentation", "fusion", "hypotheses", "inference", "total")
    timing = ", ".join(
        f"{key} {value:.2f} s" for key, value in result.timing_s.items() if key in shown
    )
    details = result.extra.get("inference") or {}
    samples = f"{details['samples']} samples, " if "samples" in details else ""
    print(f"{out}: {len(result.objects)} objects ({result.method}; {samples}{timing})")
    if details.get("fallback"):
        print(f"note: {details['fallback']}")
    print(f"picture: {out / 'completion.png'}")
    print(f"report: {out / 'report.html'}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from ipr_shapes.report_html import write_report

    out = write_report(
        Path(args.result),
        Path(args.out) if args.out else None,
        scene=Path(args.scene) if args.scene else None,
        up_camera=args.up,
        overwrite=args.overwrite,
    )
    print(out)
    return 0


@_with_progress()
def _cmd_segment(args: argparse.Namespace) -> int:
    from ipr_shapes.atomic import check_output_location
    from ipr_shapes.perception import check_objects_found, perceive_scene
    from ipr_shapes.perception.output import write_segmentation
    from ipr_shapes.scene import load_scene

    check_output_location(Path(args.out), [Path(args.scene)], overwrite=args.overwrite)
    config = _config(args)
    scene = load_scene(Path(args.scene), up_camera=args.up, frames=args.frames)
    perception = perceive_scene(
        scene, config.perception if config else None, progress=args.progress
    )
    check_objects_found(scene, perception)
    out = write_segmentation(
        scene,
        perception,
        Path(args.out),
        overwrite=args.overwrite,
        config=config.perception if config else None,
    )
    per_frame = perception.timing_s["per_frame"]
    # Loading the compiled kernels is the process's, not the frames' (0.15-0.2 s once).
    loading = perception.timing_s.get("kernels", 0.0)
    print(
        f"{out}: {len(perception.object_ids)} objects over {len(scene.frames)} frames "
        f"({1000 * sum(per_frame) / len(per_frame):.0f} ms per frame"
        + (f"; compiled kernels loaded once in {loading:.2f} s)" if loading >= 0.005 else ")")
    )
    for frame, objects in zip(scene.frames, perception.objects, strict=True):
        print(
            f"  frame {frame.index}: objects {[obj.id for obj in objects]}, "
            f"facets {sum(len(obj.facets) for obj in objects)}"
        )
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from ipr_shapes.scene import load_scene

    scene = load_scene(Path(args.scene), up_camera=args.up, frames=args.frames)
    height, width = scene.frames[0].shape
    ids = [frame.index for frame in scene.frames]
    shown = ", ".join(map(str, ids[:10])) + (", ..." if len(ids) > 10 else "")
    print(f"{scene.path}: valid scene")
    print(
        f"  frames: {len(scene.frames)} (ids {shown}; {width}x{height}), world frame from "
        f"{scene.world_frame_source}"
    )
    if scene.support_note:
        print(f"  support: {scene.support_note}")
    print(f"  pushes: {len(scene.pushes)}")
    for number, push in enumerate(scene.pushes):
        print(
            f"    {number}: frame {push.before_frame}->{push.after_frame}, "
            f"{push.distance_m * 100:.1f} cm at {push.speed_m_s * 100:.1f} cm/s"
        )
    return 0


def _cmd_suite(args: argparse.Namespace) -> int:
    from ipr_shapes.suites import SUITES, suite_scenes

    names = SUITES if args.name == "all" else [args.name]
    for name in names:
        with _progress() as progress:
            task = progress.add_task(f"suite {name}", total=None)
            scenes = suite_scenes(
                name,
                progress=lambda done, total, t=task: progress.update(
                    t, completed=done, total=total
                ),
            )
        print(f"{name}: {len(scenes)} scenes in {scenes[0].parent if scenes else '-'}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from ipr_shapes.export import export_result, load_export_manifest

    try:
        out = export_result(
            Path(args.result),
            Path(args.out) if args.out else None,
            format=args.format,
            density_kg_m3=args.density,
            collision=args.collision,
            settle=not args.no_settle,
            overwrite=args.overwrite,
        )
    except ValueError as error:  # a bad --density, reported like any input error
        raise IprError(str(error)) from error
    manifest = load_export_manifest(out)
    files = ", ".join(manifest["files"]) or "meshes/"
    settling = manifest["settling"]
    settled = (
        f"settled in {settling['simulated_s']:.1f} s simulated, objects moved up to "
        f"{1000 * settling['max_displacement_m']:.0f} mm and {settling['max_rotation_deg']:.0f} deg"
        + ("" if settling["at_rest"] else ", NOT at rest")
        if settling["enabled"]
        else "not settled"
    )
    print(
        f"{out}: {len(manifest['objects'])} objects as {args.format} ({files}; "
        f"{manifest['density_kg_m3']:g} kg/m^3, collision {manifest['collision_method']}; "
        f"{settled})"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``ipr`` and its sub-commands."""
    parser = argparse.ArgumentParser(
        prog="ipr-shapes",
        description="Complete 3D models of unknown objects in clutter by inverse physics reasoning.",
    )
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="log progress (-v) and debugging details with tracebacks (-vv)",
    )
    parser.add_argument("--version", action=_VersionAction)
    # The same flag after the sub-command; SUPPRESS keeps it from resetting the count above.
    verbosity = argparse.ArgumentParser(add_help=False)
    verbosity.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=argparse.SUPPRESS,
        help="log progress (-v) and debugging details with tracebacks (-vv)",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_command = commands.add_parser

    def add_parser(name: str, **kwargs) -> argparse.ArgumentParser:
        return add_command(name, parents=[verbosity], **kwargs)

    commands.add_parser = add_parser  # type: ignore[method-assign]

    synth = commands.add_parser(
        "synth",
        help="generate benchmark scenes with ground truth (MuJoCo)",
        description="Generate piles of YCB objects (or procedural shapes when the YCB meshes are "
        "absent) on a table, in a container or behind a front wall, with realistic "
        "depth noise, pushes (dynamic) and BOP ground truth. Scenes go to "
        "OUT_DIR/<name>/, shared models to OUT_DIR/models/.",
    )
    synth.add_argument("out_dir", metavar="OUT_DIR")
    synth.add_argument("--kind", choices=["static", "dynamic"], required=True)
    synth.add_argument("--seed", type=_seed, default=0, help="base seed (default 0)")
    synth.add_argument("--count", type=int, default=1, help="number of scenes (default 1)")
    synth.add_argument("--models", metavar="DIR", help="YCB models folder (default: shared data)")
    synth.add_argument("--width", type=int, help="image width in pixels (default 640)")
    synth.add_argument("--height", type=int, help="image height in pixels (default 480)")
    synth.add_argument("--overwrite", action="store_true", help="replace existing scenes")
    synth.set_defaults(handler=_cmd_synth)

    evaluate = commands.add_parser(
        "eval",
        help="score a result against a scene's ground truth",
        description="Voxel IoU, precision, recall and F1 (5 mm) in scene space and object space "
        "(Hungarian matching, objects visible in frame 0 only), per SCENE_FORMAT.md.",
    )
    evaluate.add_argument("scene", metavar="SCENE")
    evaluate.add_argument("result", metavar="RESULT")
    evaluate.add_argument(
        "--models", metavar="DIR", help="BOP models folder (default SCENE/../models)"
    )
    evaluate.add_argument("--json", metavar="FILE", help="also write the metrics as JSON")
    evaluate.set_defaults(handler=_cmd_eval)

    ground_truth = commands.add_parser(
        "ground-truth",
        help="write a scene's ground truth as a result (an upper bound)",
        description="Write the ground-truth objects of frame 0 as a result directory per the "
        "contract: a format reference for outside tools and the metrics' upper bound.",
    )
    ground_truth.add_argument("scene", metavar="SCENE")
    ground_truth.add_argument("-o", "--out", required=True, metavar="OUT")
    ground_truth.add_argument("--models", metavar="DIR", help="BOP models folder")
    ground_truth.add_argument("--overwrite", action="store_true")
    ground_truth.set_defaults(handler=_cmd_ground_truth)

    infer = commands.add_parser(
        "infer",
        help="complete the 3D shapes of a scene's objects (writes a result)",
        description="Perceive the scene, hypothesise hidden parts (Algorithm 1), apply the "
        "geometric constraints and infer shape posteriors; writes a result directory "
        "per SCENE_FORMAT.md (result.json, objects/<k>/best.ply and hypotheses). "
        f"The default method, {DEFAULT_METHOD}, replays gravity and the recorded pushes in "
        "MuJoCo for sampled joint shapes and weighs them by how well the simulated depth "
        "images match the observed ones (the paper's full IPR). Methods: "
        + "; ".join(f"{m.name}: {m.description}" for m in METHODS.values())
        + ". Also writes completion.png (the input beside the completed objects), labels/ "
        "(each frame's segmentation with the result's object ids) and report.html (a "
        "self-contained page: frames, pushes, segmentation, a 3-D view of the completed "
        "scene, hypotheses, timings, settings).",
    )
    infer.add_argument("scene", metavar="SCENE")
    infer.add_argument("-o", "--out", required=True, metavar="OUT")
    _add_run_options(infer)
    infer.add_argument(
        "--workers",
        type=_positive_int,
        metavar="N",
        help="threads simulating samples (default: all cores)",
    )
    infer.add_argument(
        "--no-carving",
        action="store_true",
        help="write the convex hypotheses as inferred, without removing the space the camera "
        "saw empty (ipr_shapes.carving)",
    )
    infer.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    _add_config_option(infer)
    _add_up_option(infer)
    _add_frames_option(infer)
    infer.set_defaults(handler=_cmd_infer)

    report = commands.add_parser(
        "report",
        help="(re)make a result's report.html",
        description="Write the self-contained page of a result (what 'ipr-shapes infer' writes as "
        "RESULT/report.html): the input frames with the pushes, the segmentation with the "
        "result's object ids, an interactive 3-D view of the completed scene (observed points "
        "solid, inferred shapes translucent), each object's top hypotheses, the timings and "
        "the settings. Reads the frames from the scene the result names (or --scene).",
    )
    report.add_argument("result", metavar="RESULT")
    report.add_argument(
        "-o", "--out", metavar="FILE", help="where to write it (default RESULT/report.html)"
    )
    report.add_argument(
        "--scene", metavar="SCENE", help="the scene (default: the one result.json names)"
    )
    report.add_argument("--overwrite", action="store_true", help="replace FILE if it exists")
    _add_up_option(report)
    report.set_defaults(handler=_cmd_report)

    batch = commands.add_parser(
        "batch",
        help="complete the shapes of many scenes (one result each, a summary, scores)",
        description="Run 'ipr-shapes infer' on many scenes: scene folders, folders of scene folders "
        "or glob patterns. Each result goes to OUT/<scene folder name>; a scene whose result is "
        "already there is kept (rerun a batch to finish it); a scene that fails is listed and "
        "does not stop the others. OUT/summary.md and summary.json list every scene with its "
        "status, objects, time and, where the scene has ground truth, the 'ipr-shapes eval' IoUs. "
        "Exit status 1 when any scene failed.",
    )
    batch.add_argument("scenes", nargs="+", metavar="SCENES")
    batch.add_argument("-o", "--out", required=True, metavar="OUT")
    _add_run_options(batch)
    batch.add_argument(
        "--jobs",
        type=_positive_int,
        metavar="N",
        help="scenes run at once, one process each (default: all cores; with --ray: at most "
        "N scenes at once on the cluster, default as many as it has CPUs)",
    )
    batch.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run the scenes on an existing Ray cluster: 'auto' (the one started on this "
        "machine), HOST:PORT of its head or ray://HOST:10001 (Ray Client). Needs "
        "pip install 'ipr-shapes[ray]' on every node and the scenes at the same path on every "
        "node; the results are written here",
    )
    batch.add_argument("--no-eval", action="store_true", help="do not score against ground truth")
    _add_config_option(batch)
    _add_up_option(batch)
    _add_frames_option(batch)
    batch.set_defaults(handler=_cmd_batch)

    segment = commands.add_parser(
        "segment",
        help="segment and track the objects of a scene, with facets",
        description="Remove the support, walls and robot; segment each frame into objects "
        "(supervoxels, convexity graph, spectral clustering); track ids across "
        "frames; split objects into facets. Writes OUT/labels/NNNNNN.png (the ids as "
        "pixel values, 0 = background, k = object k in every frame; an 8-bit palette PNG that "
        "viewers show in the overlay's colours), OUT/facets/NNNNNN.png, "
        "OUT/overlay/NNNNNN.png and OUT/segmentation.json.",
    )
    segment.add_argument("scene", metavar="SCENE")
    segment.add_argument("-o", "--out", required=True, metavar="OUT")
    segment.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    _add_config_option(segment)
    _add_up_option(segment)
    _add_frames_option(segment)
    segment.set_defaults(handler=_cmd_segment)

    config = commands.add_parser(
        "config",
        help="show the configuration (defaults, or a file over them) as TOML",
        description="'ipr-shapes config show' prints every setting with its default as TOML; "
        "'ipr-shapes config show --config FILE' prints the settings FILE gives over the defaults "
        "(and checks them). Save the output, edit what you need (or keep only those lines) "
        "and pass it to 'ipr-shapes infer --config FILE'.",
    )
    config.add_argument("action", choices=["show"])
    _add_config_option(config)
    config.set_defaults(handler=_cmd_config)

    check = commands.add_parser(
        "check",
        help="validate a scene directory and summarise it",
        description="Validate a scene directory against the contract and summarise it: frames, "
        "where the world frame comes from (camera poses, or the support found in frame 0 and "
        "why it was chosen) and the pushes.",
    )
    check.add_argument("scene", metavar="SCENE")
    _add_up_option(check)
    _add_frames_option(check)
    check.set_defaults(handler=_cmd_check)

    suite = commands.add_parser(
        "suite",
        help="generate (or find cached) benchmark suites",
        description="Benchmark suites are generated from fixed seeds on first use and cached "
        "outside the repository ($IPR_CACHE, default ~/.cache/ipr); the real suites (ycbv-real, "
        "bins-real) are read from the shared data.",
    )
    suite.add_argument(
        "name", choices=["ycb-static", "ycb-dynamic", "ycbv-real", "bins-real", "all"]
    )
    suite.set_defaults(handler=_cmd_suite)

    import_bag = commands.add_parser(
        "import-bag",
        help="convert a ROS 1 / ROS 2 bag into a scene folder",
        description="Convert a ROS bag (ROS 2 folder, sqlite3 or mcap; ROS 1 .bag) into a "
        "scene folder: each colour image with a registered depth image within --max-dt is a "
        "frame; intrinsics from camera_info; with --world-frame, camera poses from /tf and "
        "/tf_static; with --pusher-topic, pushes from the pusher centre's PoseStamped "
        "(published during each straight stroke). Validated before writing; written "
        "atomically. Details: docs/FORMATS.md, 'ROS bags'.",
    )
    import_bag.add_argument("bag", metavar="BAG")
    import_bag.add_argument("-o", "--out", required=True, metavar="SCENE", help="scene folder")
    import_bag.add_argument("--rgb-topic", default=BagOptionsDefaults.rgb_topic)
    import_bag.add_argument("--depth-topic", default=BagOptionsDefaults.depth_topic)
    import_bag.add_argument("--info-topic", default=BagOptionsDefaults.info_topic)
    import_bag.add_argument(
        "--world-frame",
        metavar="FRAME",
        help="z-up tf frame the camera poses are given in (default: none, a static camera "
        "whose world frame comes from frame 0's support)",
    )
    import_bag.add_argument(
        "--pusher-topic",
        metavar="TOPIC",
        help="geometry_msgs/PoseStamped of the pusher's centre during each push (needs "
        "--world-frame)",
    )
    import_bag.add_argument(
        "--max-dt",
        type=float,
        default=BagOptionsDefaults.max_dt_s,
        metavar="SECONDS",
        help="largest colour-depth stamp difference of a frame (default %(default)s s)",
    )
    import_bag.add_argument(
        "--max-tf-dt",
        type=float,
        default=BagOptionsDefaults.max_tf_dt_s,
        metavar="SECONDS",
        help="largest gap between a frame and a dynamic tf transform (default %(default)s s)",
    )
    import_bag.add_argument(
        "--pusher-radius", type=float, default=BagOptionsDefaults.pusher_radius_m, metavar="M"
    )
    import_bag.add_argument(
        "--pusher-length", type=float, default=BagOptionsDefaults.pusher_length_m, metavar="M"
    )
    import_bag.add_argument("--overwrite", action="store_true", help="replace an existing SCENE")
    import_bag.set_defaults(handler=_cmd_import_bag)

    export = commands.add_parser(
        "export",
        help="export a result for robot stacks (MJCF, URDF, SDF, OBJ, GLB)",
        description="Write a result's objects as models robot software loads directly: per "
        "object a smooth closed surface rebuilt from its 5 mm voxels, in an object frame at "
        "its centre of mass (axes as the world's), its pose, convex collision pieces and "
        "their mass and inertia at a uniform density; the support plane and the objects as "
        "free bodies (mjcf: scene.xml for MuJoCo; urdf: one per object, pybullet/MoveIt; sdf: "
        "scene.sdf for Gazebo; obj: meshes only; glb: scene.glb for viewers), at the poses "
        "the scene settles in when simulated in MuJoCo (inferred shapes are not a scene at "
        "rest on their own; how far each object moved is recorded). Every format also writes "
        "export.json (poses, moves, masses, inertias, volumes). See docs/FORMATS.md.",
    )
    export.add_argument("result", metavar="RESULT")
    export.add_argument("--format", required=True, choices=["mjcf", "urdf", "sdf", "obj", "glb"])
    export.add_argument(
        "-o", "--out", metavar="DIR", help="output folder (default RESULT/export/<format>)"
    )
    export.add_argument(
        "--density",
        type=float,
        metavar="KG_M3",
        help="uniform density of the objects in kg/m^3 (default 400, the inference's)",
    )
    export.add_argument(
        "--collision",
        choices=["hull", "coacd"],
        help="collision geometry: the convex hull (default) or CoACD's convex decomposition "
        "(needs the coacd package; seconds to minutes per object)",
    )
    export.add_argument(
        "--no-settle",
        action="store_true",
        help="export the result's poses (only separated where objects interpenetrate) "
        "instead of the poses the scene settles in",
    )
    export.add_argument("--overwrite", action="store_true", help="replace DIR if it exists")
    export.set_defaults(handler=_cmd_export)
    return parser


def _cmd_batch(args: argparse.Namespace) -> int:
    from ipr_shapes.batch import BatchOptions, find_scenes, run_batch

    if args.ray is not None:  # a bad address or a missing Ray: said before any work
        from ipr_shapes.cluster import import_ray, parse_address

        parse_address(args.ray)
        import_ray()
    scenes = find_scenes(args.scenes)
    options = BatchOptions(
        method=args.method,
        seed=args.seed,
        time_budget_s=args.time_budget,
        samples=args.samples,
        config=_config(args),
        evaluate=not args.no_eval,
        up_camera=tuple(args.up) if args.up else None,
        frames=args.frames,
    )
    with _progress() as progress:
        task = progress.add_task(f"{len(scenes)} scenes", total=len(scenes))

        def advance(outcome) -> None:
            progress.advance(task)
            if outcome.status == "failed":
                progress.console.print(f"{outcome.scene}: failed: {outcome.error}")

        summary = run_batch(
            scenes,
            Path(args.out),
            options,
            jobs=args.jobs,
            ray_address=args.ray,
            on_outcome=advance,
        )
    counts = {s: sum(o.status == s for o in summary.outcomes) for s in ("done", "kept", "failed")}
    print(
        f"{args.out}: {counts['done']} run, {counts['kept']} kept, {counts['failed']} failed "
        f"(summary: {Path(args.out) / 'summary.md'})"
    )
    return 1 if summary.failed else 0


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """The options of one scene's run, shared by ``ipr-shapes infer`` and ``ipr-shapes batch`` (per scene)."""
    parser.add_argument("--method", default=DEFAULT_METHOD, choices=list(METHODS))
    parser.add_argument(
        "--samples",
        type=_positive_int,
        metavar="N",
        help="sample exactly N joint models (reproducible with any --workers; default: as "
        "many as the time budget allows)",
    )
    parser.add_argument(
        "--seed", type=_seed, default=0, help="seed of every random choice (default 0)"
    )
    parser.add_argument(
        "--time-budget",
        type=float,
        metavar="SECONDS",
        help="wall-clock budget of the whole run; the best answer so far is written when it "
        "runs out (default: 0.8 s of sampling per object after the hypotheses)",
    )


def _add_config_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        metavar="FILE",
        help="TOML file of settings over the defaults ('ipr-shapes config show' lists them all)",
    )


def _add_up_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--up",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="the up direction in camera coordinates (x right, y down, z forward), for a "
        "scene without camera poses whose gravity the data cannot tell; e.g. 0 -1 0 for a "
        "camera held level. The support is then the plane the objects rest on among the "
        "planes within 45 degrees of perpendicular to it. Without it, gravity comes from the "
        "planes of frame 0 (the support the objects rest on: not a floor seen beyond a table, "
        "nor the tops of boxes packed in a bin)",
    )


def _cmd_config(args: argparse.Namespace) -> int:
    from ipr_shapes.config import Config, config_to_toml

    print(config_to_toml(_config(args) or Config()), end="")
    return 0


class BagOptionsDefaults:
    """``ipr-shapes import-bag``'s defaults, kept equal to ``ipr_shapes.bag.BagOptions``'s (a test checks)
    without importing rosbags to build the parser."""

    rgb_topic = "/camera/color/image_raw"
    depth_topic = "/camera/aligned_depth_to_color/image_raw"
    info_topic = "/camera/color/camera_info"
    max_dt_s = 0.02
    max_tf_dt_s = 0.1
    pusher_radius_m = 0.01
    pusher_length_m = 0.15


def _cmd_import_bag(args: argparse.Namespace) -> int:
    from ipr_shapes.bag import BagOptions, import_bag

    options = BagOptions(
        rgb_topic=args.rgb_topic,
        depth_topic=args.depth_topic,
        info_topic=args.info_topic,
        world_frame=args.world_frame,
        pusher_topic=args.pusher_topic,
        max_dt_s=args.max_dt,
        max_tf_dt_s=args.max_tf_dt,
        pusher_radius_m=args.pusher_radius,
        pusher_length_m=args.pusher_length,
    )
    out = import_bag(args.bag, args.out, options, overwrite=args.overwrite)
    print(f"{out}: scene written from {args.bag} (check it with 'ipr-shapes check {out}')")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the ``ipr`` command; returns the exit status."""
    args = build_parser().parse_args(argv)
    _configure_logging(args.verbose)
    from ipr_shapes.gl import select_gl_backend

    select_gl_backend()  # an entry point: the backend before MuJoCo loads (ipr_shapes.gl)
    try:
        return args.handler(args)
    except (IprError, FileExistsError) as error:
        if args.verbose >= 2:
            raise
        print(f"ipr-shapes {args.command}: error: {error}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except OSError as error:
        # The output could not be written (disk full, read-only, permissions): nothing half
        # written is left (ipr_shapes.atomic), so say it in one line.
        if args.verbose >= 2 or error.errno not in _WRITE_ERRNOS:
            raise
        where = f"{error.filename}: " if error.filename else ""
        print(
            f"ipr-shapes {args.command}: error: {where}cannot write: {error.strerror} "
            "(fix: free space or choose a writable output folder)",
            file=sys.stderr,
        )
        return EXIT_INPUT_ERROR
    except KeyboardInterrupt:
        print("ipr-shapes: interrupted", file=sys.stderr)
        return 130


def _configure_logging(verbosity: int) -> None:
    """Log records (warnings included) to stderr, so that stdout holds only the results."""
    from rich.console import Console
    from rich.logging import RichHandler

    level = logging.WARNING if verbosity == 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    logging.basicConfig(
        level=level,
        format="%(message)s",
        datefmt="[%X]",
        handlers=[RichHandler(show_path=False, rich_tracebacks=True, console=Console(stderr=True))],
    )


if __name__ == "__main__":
    sys.exit(main())
