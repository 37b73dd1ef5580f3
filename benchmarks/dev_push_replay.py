"""How well the simulator reproduces the pushes with the *true* shapes (docs/DESIGN_NOTES.md,
"The pushes' evidence is weak"; docs/experiments/2026-11-24-push-replay.md): the ceiling of the
evidence the pushes can give about hidden shapes.

Usage: ``python -m benchmarks.dev_push_replay [--seed 9100] [--count 10] [--friction 1.0]
[--timestep S] [--config FILE]`` (default: ``PhysicsConfig``'s step; ``--config``: a TOML
whose ``[inference.physics]`` replaces the default ``PhysicsConfig`` before ``--friction`` and
``--timestep`` apply, e.g. another contact dimensionality or solver).

Generates (or reuses) development dynamic scenes with ``ipr-shapes synth`` seeds from ``--seed`` (never
the benchmark suites). For each scene, builds ``ipr_shapes.physics``'s world from the ground-truth
models' convex hulls at their true frame-0 poses (benchmark code may read the ground truth;
inference never does), with the support the perception found, settles it, replays the
recorded pushes and, after each push, compares every object's simulated motion with its true
motion since frame 0: the mean distance (m) between the hull's vertices moved by each. Prints
the median error over the (object, frame) pairs that truly moved more than 5 mm, their median
true motion, and the median error of those that did not move. The benchmark page's replay
ladder (``benchmarks.replay``) runs this as its last rung, at the default ``PhysicsConfig``.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from pathlib import Path

import numpy as np


@functools.lru_cache(maxsize=4)
def _support_and_walls(path: Path) -> tuple:
    """The frame-0 planes perception finds in scene ``path`` (cached: several worlds replay
    one scene)."""
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.scene import load_scene

    return tuple(perceive_scene(load_scene(path)).planes[0])


def replay_errors(path: Path, config) -> list[tuple[float, float]]:
    """(simulated-motion error, true motion) in metres per (object, later frame) of one scene
    replayed in ``ipr_shapes.physics``'s world with ``config`` (a ``PhysicsConfig``)."""
    import trimesh

    from ipr_shapes.physics import Body, build_world
    from ipr_shapes.scene import default_models_dir, load_ground_truth, load_model, load_scene

    scene = load_scene(path)
    truth = load_ground_truth(path)
    planes = _support_and_walls(Path(path))
    world_from_camera = {f.index: f.world_from_camera for f in scene.frames}
    bodies, start_poses = [], []
    for entry in truth[0]:
        model = load_model(default_models_dir(path), entry.obj_id)
        hull = trimesh.Trimesh(model.vertices, model.faces).convex_hull
        pose = world_from_camera[0] @ entry.camera_from_model
        vertices = np.asarray(hull.vertices) @ pose[:3, :3].T + pose[:3, 3]
        bodies.append(Body(vertices, np.asarray(hull.faces)))
        start_poses.append(pose)
    world = build_world(bodies, planes, config, pusher=scene.pusher)
    world.settle()
    settled = world.poses()
    rows = []
    for frame in sorted(truth)[1:]:
        for push in scene.pushes:
            if push.after_frame == frame:
                world.push(push)
        now = world.poses()
        for k, entry in enumerate(truth[0]):
            later = next((e for e in truth[frame] if e.obj_id == entry.obj_id), None)
            if later is None:
                continue
            true_motion = (world_from_camera[frame] @ later.camera_from_model) @ np.linalg.inv(
                start_poses[k]
            )
            simulated = now[k] @ np.linalg.inv(settled[k])
            points = bodies[k].vertices

            def moved(transform: np.ndarray, points: np.ndarray = points) -> np.ndarray:
                return points @ transform[:3, :3].T + transform[:3, 3]

            error = np.linalg.norm(moved(simulated) - moved(true_motion), axis=1).mean()
            motion = np.linalg.norm(moved(true_motion) - points, axis=1).mean()
            rows.append((float(error), float(motion)))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=9100)
    parser.add_argument("--count", type=int, default=10)
    parser.add_argument("--friction", type=float, default=1.0)
    parser.add_argument("--timestep", type=float, default=None)
    parser.add_argument("--scenes", type=Path, default=Path("/tmp/ipr-dev-inference"))
    parser.add_argument("--config", type=Path, help="a TOML configuration (ipr-shapes config show)")
    args = parser.parse_args(argv)
    if not (args.friction > 0 and (args.timestep or 1) > 0 and args.count >= 1):
        parser.error("--friction and --timestep must be positive and --count at least 1")
    from benchmarks.common import development_scenes
    from ipr_shapes.physics import PhysicsConfig

    config = PhysicsConfig()
    if args.config is not None:
        from ipr_shapes.config import read_config
        from ipr_shapes.errors import IprError

        try:
            config = read_config(args.config).inference.physics
        except IprError as error:
            parser.exit(2, f"error: {error}\n")
    config = dataclasses.replace(config, friction=args.friction)
    if args.timestep is not None:
        config = dataclasses.replace(config, timestep_s=args.timestep)
    rows = []
    for path in development_scenes(args.scenes, args.seed, args.count):
        rows += replay_errors(path, config)
    errors, motions = np.array(rows).reshape(-1, 2).T
    moved = motions > 0.005
    print(
        f"{len(rows)} (object, frame) pairs, {moved.sum()} moved more than 5 mm "
        f"(median true motion {np.median(motions[moved]) * 1e3:.1f} mm): simulated motion off by "
        f"a median {np.median(errors[moved]) * 1e3:.1f} mm (quartiles "
        f"{np.percentile(errors[moved], 25) * 1e3:.1f}-{np.percentile(errors[moved], 75) * 1e3:.1f}"
        f" mm); objects that did not move: {np.median(errors[~moved]) * 1e3:.1f} mm"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
