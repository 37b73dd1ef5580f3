"""Development measurement of the support choice on real frames (docs/DESIGN_NOTES.md, "The
support is the plane the objects rest on"; docs/experiments/2026-11-26-support-choice.md).

Usage: ``python -m benchmarks.dev_support [--sets bins ycbv uoislab] [--data DIR]
[--overlays DIR] [--json FILE]``.

Runs ``ipr``'s perception (``load_scene`` then ``perceive_scene``, as ``ipr-shapes segment`` does) on
the shared real sets and prints, per scene:

- **bins** (``bins_real``: boxes packed in a bin, no camera pose): whether the chosen support
  lies under the boxes: the median over the ground-truth boxes of the median signed distance
  (m) of each box's model surface points (1000, fixed seed) to the frame-0 support, the lowest
  box's, and the share of boxes whose median is above the support; and the share of boxes
  segmented with F >= 0.75 (``ipr_shapes.segmentation_metrics.segmentation_scores`` of the frame's
  labels against the ``mask_visib`` masks). Neat arrangements (000-018) and piles (020-028)
  are summed apart.
- **ycbv** (``ycbv_real``): the share of (object, frame) rows with F >= 0.75 against the
  rendered ground-truth masks (``ground_truth_masks``), every frame.
- **uoislab** (``real_unlabelled``: no labels): the support's height above the lowest and
  below the highest frame-0 points, for the overlays a person judges (``--overlays`` writes
  ``ipr-shapes segment``'s outputs there, one folder per scene).

Every set also gives the median perception ms per frame (``timing_s["per_frame"]``, what
``segmentation.json`` records). Ground truth is read for scoring only.

The "before" figures come from another checkout's ``ipr`` ahead on the path, with this
checkout's ``benchmarks`` package: ``PYTHONPATH=/work/baseline/src:. python -m
benchmarks.dev_support``; the first line printed names the ``ipr`` measured.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

#: Scenes of each set (folders under the shared data).
SETS = {
    "bins": ("bins_real", [f"bins_{n:03d}" for n in range(0, 30, 2)]),
    "ycbv": ("ycbv_real", ["ycbv_0000", "ycbv_0001"]),
    "uoislab": ("real_unlabelled", [f"uoislab_{n:03d}" for n in range(6)]),
}
#: The neat bin arrangements; 020-028 are piles.
NEAT_BINS = {f"bins_{n:03d}" for n in range(0, 20, 2)}


def _support(perception) -> tuple[np.ndarray, float]:
    """Frame 0's support (unit normal, offset) in the world frame."""
    plane = next(p for p in perception.planes[0] if p.kind == "support")
    return np.asarray(plane.normal, float), float(plane.offset)


def _perceive(scene_path: Path, overlays: Path | None):
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.scene import load_scene

    scene = load_scene(scene_path)
    perception = perceive_scene(scene, with_free_space=False)
    if overlays is not None:
        from ipr_shapes.perception.output import write_segmentation

        write_segmentation(scene, perception, overlays / scene_path.name, overwrite=True)
    return scene, perception


def measure_bins(scene_path: Path, overlays: Path | None) -> dict:
    """Support under the boxes and F >= 0.75 share of one bins scene (module doc)."""
    import trimesh
    from PIL import Image

    from ipr_shapes.scene import default_models_dir, load_ground_truth, load_model
    from ipr_shapes.segmentation_metrics import segmentation_scores

    scene, perception = _perceive(scene_path, overlays)
    normal, offset = _support(perception)
    frame = scene.frames[0]
    models = default_models_dir(scene_path)
    distances = []
    for pose in load_ground_truth(scene_path)[frame.index]:
        mesh = load_model(models, pose.obj_id)
        surface, _ = trimesh.sample.sample_surface(mesh, 1000, seed=0)
        world = frame.world_from_camera @ pose.camera_from_model
        points = surface @ world[:3, :3].T + world[:3, 3]
        distances.append(float(np.median(points @ normal + offset)))
    labels = np.zeros(frame.shape, dtype=np.int32)
    for k in range(len(distances)):
        mask_path = scene_path / "mask_visib" / f"{frame.index:06d}_{k:06d}.png"
        with Image.open(mask_path) as image:
            labels[np.asarray(image.convert("L")) > 0] = k + 1
    scores = segmentation_scores(perception.labels[0], labels)
    return {
        "scene": scene_path.name,
        "boxes": len(distances),
        "median_distance_m": float(np.median(distances)),
        "lowest_box_m": float(np.min(distances)),
        "share_above": float(np.mean(np.asarray(distances) > 0)),
        "visible": scores.n_visible,
        "f75": int(round(scores.share_f75 * scores.n_visible)),
        "mean_f": scores.f_measure,
        "ms_per_frame": 1000 * statistics.median(perception.timing_s["per_frame"]),
        "note": getattr(scene, "support_note", ""),
    }


def measure_ycbv(scene_path: Path, overlays: Path | None) -> dict:
    """F >= 0.75 rows of every frame of one ycbv scene against the rendered masks."""
    from ipr_shapes.segmentation_metrics import ground_truth_masks, segmentation_scores

    scene, perception = _perceive(scene_path, overlays)
    rows = good = 0
    for frame, labels in zip(scene.frames, perception.labels, strict=True):
        gt, _, _ = ground_truth_masks(scene_path, frame.index, frame=frame)
        scores = segmentation_scores(labels, gt)
        rows += scores.n_visible
        good += int(round(scores.share_f75 * scores.n_visible))
    return {
        "scene": scene_path.name,
        "rows": rows,
        "f75": good,
        "ms_per_frame": 1000 * statistics.median(perception.timing_s["per_frame"]),
    }


def measure_uoislab(scene_path: Path, overlays: Path | None) -> dict:
    """Where the support lies among the frame's points (no labels: the overlays are judged)."""
    scene, perception = _perceive(scene_path, overlays)
    normal, offset = _support(perception)
    frame = scene.frames[0]
    heights = (frame.points_world()[frame.depth_m > 0]) @ normal + offset
    return {
        "scene": scene_path.name,
        "below_m": float(-np.percentile(heights, 1)),
        "above_m": float(np.percentile(heights, 99)),
        "share_below": float(np.mean(heights < -0.02)),
        "objects": len(perception.object_ids),
        "ms_per_frame": 1000 * statistics.median(perception.timing_s["per_frame"]),
        "note": getattr(scene, "support_note", ""),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.dev_support")
    parser.add_argument("--sets", nargs="+", choices=list(SETS), default=list(SETS))
    parser.add_argument("--data", type=Path, help="shared data folder (default: ipr's own)")
    parser.add_argument("--overlays", type=Path, help="write ipr-shapes segment's outputs here")
    parser.add_argument("--json", type=Path, help="also write every figure as JSON")
    args = parser.parse_args(argv)

    import ipr_shapes
    from ipr_shapes.data import shared_data_dir

    data = args.data or shared_data_dir()
    if data is None:
        print("shared data not found (pass --data)", file=sys.stderr)
        return 2
    print(f"ipr from {Path(ipr_shapes.__file__).parent}")
    measure = {"bins": measure_bins, "ycbv": measure_ycbv, "uoislab": measure_uoislab}
    results: dict[str, list[dict]] = {}
    for name in args.sets:
        folder, scenes = SETS[name]
        results[name] = []
        for scene in scenes:
            path = Path(data) / folder / scene
            if not path.is_dir():
                continue
            row = measure[name](path, args.overlays)
            results[name].append(row)
            figures = {k: v for k, v in row.items() if k not in ("scene", "note")}
            shown = ", ".join(
                f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in figures.items()
            )
            print(f"{name} {scene}: {shown}")
            if row.get("note"):
                print(f"    support: {row['note']}")
        _summary(name, results[name])
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    return 0


def _summary(name: str, rows: list[dict]) -> None:
    if not rows:
        return
    ms = statistics.median(row["ms_per_frame"] for row in rows)
    if name == "bins":
        for label, group in (
            ("neat 000-018", [r for r in rows if r["scene"] in NEAT_BINS]),
            ("piles 020-028", [r for r in rows if r["scene"] not in NEAT_BINS]),
        ):
            if not group:
                continue
            good = sum(r["f75"] for r in group)
            visible = sum(r["visible"] for r in group)
            under = sum(r["lowest_box_m"] > 0 for r in group)
            print(
                f"bins {label}: support under every box in {under} of {len(group)} scenes; "
                f"boxes above it {np.mean([r['share_above'] for r in group]):.3f}; median box "
                f"distance {statistics.median(r['median_distance_m'] for r in group):+.3f} m; "
                f"F >= 0.75 {good} of {visible} ({good / max(visible, 1):.3f})"
            )
    elif name == "ycbv":
        good, total = sum(r["f75"] for r in rows), sum(r["rows"] for r in rows)
        print(f"ycbv: F >= 0.75 {good} of {total} rows ({good / max(total, 1):.3f})")
    print(f"{name}: median {ms:.0f} ms per frame")


if __name__ == "__main__":
    raise SystemExit(main())
