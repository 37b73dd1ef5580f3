"""Perception speed-ups checked side by side: same labels, CPU time per frame.

Two versions of the code (two source trees, e.g. a ``git archive`` of main and a worktree) run
in alternating child processes on the same scenes:

- ``labels``: each version writes every frame's tracked labels, untracked segment labels and
  facet labels to an ``.npz``; the two files are compared pixel for pixel and every frame that
  differs is listed.
- ``time``: each version runs in its own child process, after one untimed pass that loads
  the compiled kernels; scene by scene, one version perceives it and then the other (the
  first alternates between rounds). Each frame's time is the perception's own per-frame
  figure measured in CPU time of that process (``time.process_time``, BLAS limited to one
  thread), not wall time, so that other work on a shared machine counts less. Reported per
  set: the median ms per frame of each version and the median of the per-scene ratios.

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
arrays = {}
with one_thread():
    if mode == "serve":
        for scene in loaded.values():  # load the compiled kernels of every path first
            perception.perceive_scene(scene, with_free_space=False)
        print("ready", flush=True)
        for line in sys.stdin:  # one scene per request: its CPU seconds per frame
            result = perception.perceive_scene(loaded[line.strip()], with_free_space=False)
            print(json.dumps(result.timing_s["per_frame"]), flush=True)
        sys.exit(0)
    for name, scene in loaded.items():
        result = perception.perceive_scene(scene, with_free_space=False)
        for index, labels in enumerate(result.labels):
            arrays[f"{name}|{index}|labels"] = labels
            arrays[f"{name}|{index}|segments"] = result.segmentations[index].labels
            arrays[f"{name}|{index}|facets"] = result.facet_labels[index]
np.savez_compressed(out, **arrays)
"""


def _environment(src: Path) -> dict:
    """The environment of a child on the code under ``src`` (the repository root is on the
    path for ``benchmarks.common``)."""
    root = Path(__file__).resolve().parents[1]
    return dict(os.environ, PYTHONPATH=f"{src}{os.pathsep}{root}")


def _run(src: Path, mode: str, out: Path, scenes: list[str]) -> None:
    """One child process on the code under ``src``."""
    subprocess.run(
        [sys.executable, "-c", _CHILD, mode, str(out), json.dumps(scenes)],
        env=_environment(src),
        check=True,
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
) -> dict[str, tuple[float, float, float]]:
    """{set: (old, new, ratio)}: the median CPU ms per frame of each version over the set's
    frames and rounds, and the median over the set's scenes and rounds of the per-scene ratio
    new / old. Both versions stay loaded in their own process; scene by scene, one perceives
    and then the other (the first alternates between rounds), so that each pair of figures
    is taken under the same load."""
    scenes = [scene for members in sets.values() for scene in members]
    servers = {}
    for tag, src in (("old", old), ("new", new)):
        servers[tag] = subprocess.Popen(
            [sys.executable, "-c", _CHILD, "serve", "-", json.dumps(scenes)],
            env=_environment(src),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        if servers[tag].stdout.readline().strip() != "ready":
            raise RuntimeError(f"the {tag} version did not start")
    frames: dict[str, dict[str, list[float]]] = {"old": {}, "new": {}}
    ratios: dict[str, list[float]] = {}
    try:
        for number in range(rounds):
            for name, members in sets.items():
                for scene in members:
                    seconds = {}
                    for tag in ("old", "new") if number % 2 == 0 else ("new", "old"):
                        servers[tag].stdin.write(scene + "\n")
                        servers[tag].stdin.flush()
                        seconds[tag] = json.loads(servers[tag].stdout.readline())
                        frames[tag].setdefault(name, []).extend(1000 * s for s in seconds[tag])
                    ratios.setdefault(name, []).append(
                        float(np.median(seconds["new"]) / np.median(seconds["old"]))
                    )
            print(f"round {number} done", flush=True)
    finally:
        for server in servers.values():
            server.stdin.close()
            server.wait()
    return {
        name: (
            float(np.median(frames["old"][name])),
            float(np.median(frames["new"][name])),
            float(np.median(ratios[name])),
        )
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
    args = parser.parse_intermixed_args(argv)
    sets = _sets(args)
    if not sets:
        parser.error("give scene folders or --set NAME=DIR,DIR")
    if any(not name or not members for name, members in sets.items()):
        parser.error("each --set is NAME=DIR,DIR,... (a name and at least one scene folder)")
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, got {args.rounds}")
    for src in (args.old_src, args.new_src):
        if not (src / "ipr_shapes").is_dir():
            parser.error(f"{src} holds no ipr_shapes package; pass the src folder")
    for scene in (scene for members in sets.values() for scene in members):
        if not (Path(scene) / "scene_camera.json").is_file():
            parser.error(f"{scene} is not a scene folder (no scene_camera.json)")
    if args.mode == "labels":
        scenes = [scene for members in sets.values() for scene in members]
        differ = compare_labels(args.old_src, args.new_src, scenes)
        for line in differ:
            print(line)
        return 1 if differ else 0
    figures = time_versions(args.old_src, args.new_src, sets, args.rounds)
    print("| set | old ms/frame | new ms/frame | new/old (median of scene ratios) |")
    print("|---|---|---|---|")
    for name, (before, after, ratio) in figures.items():
        print(f"| {name} | {before:.1f} | {after:.1f} | {ratio:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
