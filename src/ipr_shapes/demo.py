"""``make demo``: the main job end to end on a generated scene.

Generates a dynamic scene, segments it, completes the objects' shapes with the full method
(``ipr+action+uniform``: gravity and the recorded pushes replayed in MuJoCo), scores the result
next to the Collision Checker baseline, and writes the ground truth as a result. Usage:
``python -m ipr_shapes.demo OUT_DIR``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

DEMO_SEED = 7


def run_demo(out_dir: Path) -> int:
    """Generate a dynamic scene, segment it, infer shapes, score them; print where things are."""
    from ipr_shapes.gl import select_gl_backend

    select_gl_backend()  # an entry point: the backend before MuJoCo loads (ipr_shapes.gl)
    from ipr_shapes.data import ycb_models_dir
    from ipr_shapes.ground_truth import write_ground_truth_result
    from ipr_shapes.methods import DEFAULT_METHOD
    from ipr_shapes.metrics import evaluate, format_table
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.perception.output import write_segmentation
    from ipr_shapes.pipeline import infer
    from ipr_shapes.scene import load_scene
    from ipr_shapes.synth import generate_scene

    out_dir = out_dir.resolve()
    source = "YCB meshes" if ycb_models_dir() else "procedural shapes (YCB meshes not found)"
    print(f"ipr-shapes demo: generating a dynamic scene from {source} ...")
    started = time.perf_counter()
    scene_path = generate_scene(
        out_dir / "scenes",
        kind="dynamic",
        seed=DEMO_SEED,
        arrangement="table",
        name="demo",
        overwrite=True,
    )
    print(f"  scene:   {scene_path}  ({time.perf_counter() - started:.1f} s)")
    print(f"  preview: {scene_path / 'preview.png'}")
    scene = load_scene(scene_path)
    print(f"  frames:  {len(scene.frames)}, pushes: {len(scene.pushes)} (validated)")

    segmentation = write_segmentation(
        scene, perceive_scene(scene), out_dir / "segmentation", overwrite=True
    )
    print(f"  segmentation: {segmentation / 'overlay'} (tracked objects and facets)")
    print("ipr-shapes demo: completing the objects' shapes (IPR: gravity and pushes in MuJoCo) ...")
    started = time.perf_counter()
    result_path = infer(scene_path, out_dir / "result", method=DEFAULT_METHOD, overwrite=True)
    print(
        f"  result:  {result_path}  ({time.perf_counter() - started:.1f} s; "
        "objects/<k>/best.ply are the completed shapes, world frame, metres)"
    )
    print(f"  picture: {result_path / 'completion.png'} (input beside the completed objects)")
    print(f"  report:  {result_path / 'report.html'} (frames, pushes, segmentation, a 3-D view)")
    print(format_table(evaluate(scene_path, result_path)))
    print("ipr-shapes demo: the Collision Checker baseline (no physics), for comparison ...")
    baseline = infer(
        scene_path, out_dir / "collision-checker", method="collision-checker", overwrite=True
    )
    print(format_table(evaluate(scene_path, baseline)))
    truth = write_ground_truth_result(scene_path, out_dir / "ground-truth", overwrite=True)
    print(f"  ground truth written as a result (the upper bound): {truth}")
    print(
        "ipr-shapes demo: done. Open the preview and the overlays to see the scene; "
        f"'ipr-shapes eval {scene_path} RESULT' scores any result directory against it."
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point: ``python -m ipr_shapes.demo [OUT_DIR]`` (default ``out/demo``)."""
    argv = sys.argv[1:] if argv is None else argv
    from ipr_shapes.errors import IprError

    try:
        return run_demo(Path(argv[0] if argv else "out/demo"))
    except IprError as error:
        print(f"ipr-shapes demo: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
