"""The ``ipr`` command: one sub-command per job.

Outside tools call these exactly so (the scene contract's interface):

    ipr synth OUT_DIR --kind {static,dynamic} --seed S --count N
    ipr eval SCENE RESULT [--models DIR] [--json FILE]

Errors in the input are reported as one line naming the file, the problem and the fix, with a
non-zero exit status and no traceback (``-v`` shows logs, ``-vv`` also tracebacks).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from ipr.atomic import write_json
from ipr.errors import IprError
from ipr.methods import DEFAULT_METHOD, METHODS

log = logging.getLogger("ipr")

EXIT_INPUT_ERROR = 2


def _progress():
    """A rich progress bar on stderr (disabled when stderr is not a terminal)."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        disable=not console.is_terminal,
    )


def _cmd_synth(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ipr.synth import SynthConfig, generate_scenes

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
    from ipr.metrics import evaluate, format_table

    evaluation = evaluate(
        Path(args.scene), Path(args.result), models_dir=Path(args.models) if args.models else None
    )
    print(format_table(evaluation))
    if args.json:
        write_json(Path(args.json), evaluation.to_dict())
    return 0


def _cmd_ground_truth(args: argparse.Namespace) -> int:
    from ipr.ground_truth import write_ground_truth_result

    path = write_ground_truth_result(
        Path(args.scene),
        Path(args.out),
        models_dir=Path(args.models) if args.models else None,
        overwrite=args.overwrite,
    )
    print(path)
    return 0


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
    from ipr.config import read_config

    return read_config(Path(args.config))


def _cmd_infer(args: argparse.Namespace) -> int:
    import dataclasses

    from ipr.config import Config
    from ipr.pipeline import infer
    from ipr.result import load_result

    config = _config(args)
    if args.no_carving:
        config = config or Config()
        config = dataclasses.replace(
            config, carving=dataclasses.replace(config.carving, enabled=False)
        )
    out = infer(
        Path(args.scene),
        Path(args.out),
        method=args.method,
        seed=args.seed,
        time_budget_s=args.time_budget,
        workers=args.workers,
        samples=args.samples,
        config=config,
        overwrite=args.overwrite,
        up_camera=args.up,
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
    return 0


def _cmd_segment(args: argparse.Namespace) -> int:
    from ipr.perception import perceive_scene
    from ipr.perception.output import write_segmentation
    from ipr.scene import load_scene

    config = _config(args)
    scene = load_scene(Path(args.scene), up_camera=args.up)
    perception = perceive_scene(scene, config.perception if config else None)
    out = write_segmentation(scene, perception, Path(args.out), overwrite=args.overwrite)
    per_frame = perception.timing_s["per_frame"]
    print(
        f"{out}: {len(perception.object_ids)} objects over {len(scene.frames)} frames "
        f"({1000 * sum(per_frame) / len(per_frame):.0f} ms per frame)"
    )
    for frame, objects in zip(scene.frames, perception.objects, strict=True):
        print(
            f"  frame {frame.index}: objects {[obj.id for obj in objects]}, "
            f"facets {sum(len(obj.facets) for obj in objects)}"
        )
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from ipr.scene import load_scene

    scene = load_scene(Path(args.scene), up_camera=args.up)
    height, width = scene.frames[0].shape
    print(f"{scene.path}: valid scene")
    print(
        f"  frames: {len(scene.frames)} ({width}x{height}), world frame from {scene.world_frame_source}"
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
    from ipr.suites import SUITES, suite_scenes

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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``ipr`` and its sub-commands."""
    parser = argparse.ArgumentParser(
        prog="ipr",
        description="Complete 3D models of unknown objects in clutter by inverse physics reasoning.",
    )
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="log progress (-v) and debugging details with tracebacks (-vv)",
    )
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
    synth.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
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
        + ". Also writes completion.png: the input beside the completed objects.",
    )
    infer.add_argument("scene", metavar="SCENE")
    infer.add_argument("-o", "--out", required=True, metavar="OUT")
    infer.add_argument("--method", default=DEFAULT_METHOD, choices=list(METHODS))
    infer.add_argument(
        "--workers",
        type=_positive_int,
        metavar="N",
        help="processes simulating samples (default: all cores; 1 = no pool)",
    )
    infer.add_argument(
        "--samples",
        type=_positive_int,
        metavar="N",
        help="sample exactly N joint models (reproducible with any --workers; default: as "
        "many as the time budget allows)",
    )
    infer.add_argument(
        "--seed", type=int, default=0, help="seed of every random choice (default 0)"
    )
    infer.add_argument(
        "--no-carving",
        action="store_true",
        help="write the convex hypotheses as inferred, without removing the space the camera "
        "saw empty (ipr.carving)",
    )
    infer.add_argument(
        "--time-budget",
        type=float,
        metavar="SECONDS",
        help="wall-clock budget of the whole run; the best answer so far is written when it "
        "runs out (default: 1.75 s of inference per object after the hypotheses)",
    )
    infer.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    _add_config_option(infer)
    _add_up_option(infer)
    infer.set_defaults(handler=_cmd_infer)

    segment = commands.add_parser(
        "segment",
        help="segment and track the objects of a scene, with facets",
        description="Remove the support, walls and robot; segment each frame into objects "
        "(supervoxels, convexity graph, spectral clustering); track ids across "
        "frames; split objects into facets. Writes OUT/labels/NNNNNN.png (uint16, "
        "0 = background, k = object k in every frame), OUT/facets/NNNNNN.png, "
        "OUT/overlay/NNNNNN.png and OUT/segmentation.json.",
    )
    segment.add_argument("scene", metavar="SCENE")
    segment.add_argument("-o", "--out", required=True, metavar="OUT")
    segment.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    _add_config_option(segment)
    _add_up_option(segment)
    segment.set_defaults(handler=_cmd_segment)

    config = commands.add_parser(
        "config",
        help="show the configuration (defaults, or a file over them) as TOML",
        description="'ipr config show' prints every setting with its default as TOML; "
        "'ipr config show --config FILE' prints the settings FILE gives over the defaults "
        "(and checks them). Save the output, edit what you need (or keep only those lines) "
        "and pass it to 'ipr infer --config FILE'.",
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
    check.set_defaults(handler=_cmd_check)

    suite = commands.add_parser(
        "suite",
        help="generate (or find cached) benchmark suites",
        description="Benchmark suites are generated from fixed seeds on first use and cached "
        "outside the repository ($IPR_CACHE, default ~/.cache/ipr).",
    )
    suite.add_argument("name", choices=["ycb-static", "ycb-dynamic", "ycbv-real", "all"])
    suite.set_defaults(handler=_cmd_suite)
    return parser


def _add_config_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        metavar="FILE",
        help="TOML file of settings over the defaults ('ipr config show' lists them all)",
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
    from ipr.config import Config, config_to_toml

    print(config_to_toml(_config(args) or Config()), end="")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the ``ipr`` command; returns the exit status."""
    args = build_parser().parse_args(argv)
    _configure_logging(args.verbose)
    try:
        return args.handler(args)
    except (IprError, FileExistsError) as error:
        if args.verbose >= 2:
            raise
        print(f"ipr {args.command}: error: {error}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except KeyboardInterrupt:
        print("ipr: interrupted", file=sys.stderr)
        return 130


def _configure_logging(verbosity: int) -> None:
    from rich.logging import RichHandler

    level = logging.WARNING if verbosity == 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    logging.basicConfig(
        level=level,
        format="%(message)s",
        datefmt="[%X]",
        handlers=[RichHandler(show_path=False, rich_tracebacks=True)],
    )


if __name__ == "__main__":
    sys.exit(main())
