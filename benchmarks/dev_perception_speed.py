"""Perception speed-ups checked side by side: same labels, CPU time per frame.

Two versions of the code (two source trees, e.g. a ``git archive`` of main and a worktree) run
in alternating child processes on the same scenes:

- ``labels``: each version writes every frame's tracked labels, untracked segment labels and
  facet labels to an ``.npz``; the two files are compared pixel for pixel and every frame that
  differs is listed.
- ``time``: each version perceives the scenes in one child process per round (the rounds
  alternate old, new, old, new, ...), after one untimed pass that loads the compiled kernels;
  each frame's time is the CPU time of that process (``time.process_time``, BLAS limited to one
  thread), not wall time, so that other work on a shared machine counts little. Reported: the
  median over rounds of each set's median ms per frame, and the ratio new / old.

``python -m benchmarks.dev_perception_speed labels --old-src A/src --new-src B/src SCENE...``
and ``... time --rounds 3 ...``; scenes are folders (``--set NAME=DIR,DIR`` groups them).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

_CHILD = r"""
import json, sys, time
from pathlib import Path
import numpy as np
from benchmarks.common import one_thread
from ipr_shapes.scene import load_scene
import ipr_shapes.perception as perception

mode, out, scenes = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
# The perception's own per-frame figures, measured in this process's CPU time.
perception.time = type("CpuClock", (), {"perf_counter": staticmethod(time.process_time)})
loaded = {scene: load_scene(Path(scene)) for scene in scenes}
arrays, times = {}, {}
with one_thread():
    if mode == "time":
        for scene in loaded.values():  # load the compiled kernels of every path first
            perception.perceive_scene(scene, with_free_space=False)
    for name, scene in loaded.items():
        result = perception.perceive_scene(scene, with_free_space=False)
        times[name] = [float(s) for s in result.timing_s["per_frame"]]
        if mode == "labels":
            for index, labels in enumerate(result.labels):
                arrays[f"{name}|{index}|labels"] = labels
                arrays[f"{name}|{index}|segments"] = result.segmentations[index].labels
                arrays[f"{name}|{index}|facets"] = result.facet_labels[index]
if mode == "labels":
    np.savez_compressed(out, **arrays)
else:
    Path(out).write_text(json.dumps(times))
"""


def _run(src: Path, mode: str, out: Path, scenes: list[str]) -> None:
    """One child process on the code under ``src`` (the repository root is on the path for
    ``benchmarks.common``)."""
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=f"{src}{os.pathsep}{root}")
    subprocess.run(
        [sys.executable, "-c", _CHILD, mode, str(out), json.dumps(scenes)], env=env, check=True
    )


def compare_labels(old: Path, new: Path, scenes: list[str]) -> list[str]:
    """Frames whose labels differ between the two versions ('scene|frame|kind: n pixels')."""
    with tempfile.TemporaryDirectory() as folder:
        files = []
        for tag, src in (("old", old), ("new", new)):
            path = Path(folder) / f"{tag}.npz"
            _run(src, "labels", path, scenes)
            files.append(np.load(path))
        before, after = files
        differ = []
        if sorted(before.files) != sorted(after.files):
            differ.append("the versions labelled different frames")
        for key in sorted(set(before.files) & set(after.files)):
            a, b = before[key], after[key]
            if a.shape != b.shape or not np.array_equal(a, b):
                count = int((a != b).sum()) if a.shape == b.shape else a.size
                differ.append(f"{key}: {count} pixels")
        print(f"{len(before.files)} label images compared, {len(differ)} differ")
        return differ


def time_versions(
    old: Path, new: Path, sets: dict[str, list[str]], rounds: int
) -> dict[str, tuple[float, float]]:
    """{set: (old, new) median over rounds of the set's median CPU ms per frame}."""
    scenes = [scene for members in sets.values() for scene in members]
    per_round: dict[str, dict[str, list[float]]] = {"old": {}, "new": {}}
    with tempfile.TemporaryDirectory() as folder:
        for number in range(rounds):
            for tag, src in (("old", old), ("new", new)):
                path = Path(folder) / f"{tag}{number}.json"
                _run(src, "time", path, scenes)
                times = json.loads(path.read_text())
                for name, members in sets.items():
                    frames = [1000 * s for scene in members for s in times[scene]]
                    per_round[tag].setdefault(name, []).append(float(np.median(frames)))
                    print(f"round {number} {tag} {name}: {np.median(frames):.1f} ms", flush=True)
    return {
        name: (float(np.median(per_round["old"][name])), float(np.median(per_round["new"][name])))
        for name in sets
    }


def _sets(args: argparse.Namespace) -> dict[str, list[str]]:
    sets = {}
    for item in args.set or []:
        name, _, folders = item.partition("=")
        sets[name] = [str(Path(f)) for f in folders.split(",") if f]
    if args.scenes:
        sets["scenes"] = [str(Path(s)) for s in args.scenes]
    return sets


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=["labels", "time"])
    parser.add_argument("--old-src", type=Path, required=True, help="src folder of the old code")
    parser.add_argument("--new-src", type=Path, required=True, help="src folder of the new code")
    parser.add_argument("--set", action="append", help="NAME=SCENE,SCENE,... (repeatable)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (time)")
    parser.add_argument("scenes", nargs="*", help="scene folders")
    args = parser.parse_args(argv)
    sets = _sets(args)
    if not sets:
        parser.error("give scene folders or --set NAME=DIR,DIR")
    for src in (args.old_src, args.new_src):
        if not (src / "ipr_shapes").is_dir():
            parser.error(f"{src} holds no ipr_shapes package; pass the src folder")
    if args.mode == "labels":
        scenes = [scene for members in sets.values() for scene in members]
        differ = compare_labels(args.old_src, args.new_src, scenes)
        for line in differ:
            print(line)
        return 1 if differ else 0
    figures = time_versions(args.old_src, args.new_src, sets, args.rounds)
    print("| set | old ms/frame | new ms/frame | new/old |\n|---|---|---|---|")
    for name, (before, after) in figures.items():
        print(f"| {name} | {before:.1f} | {after:.1f} | {after / before:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
