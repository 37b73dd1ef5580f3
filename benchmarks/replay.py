"""The replay ladder: how far the simulator is from the data (issue 29, item 4).

The ``replay`` section of docs/BENCHMARKS.md (``python -m benchmarks.run --only replay``), or
printed with ``python -m benchmarks.replay [--limit N] [--scene DIR ...]``.

Each generated dynamic scene's recorded pushes are replayed in worlds that step by step move
from the generator's own simulation to the world inference builds (``ipr_shapes.physics``), and every
object's simulated motion since frame 0 is compared with its true motion after each push: the
mean distance (mm) between the true shape's convex-hull vertices moved by each. Figures are
over the (object, frame) pairs that truly moved more than ``MOVED_M`` (median and quartiles).
The rungs (``RUNGS``):

a. the generator's world (``ipr_shapes.synth.piles.PileWorld``) rebuilt from the scene's seed and
   replayed from its own integration state at frame 0 (the ladder's zero: the generator's
   own simulation, which the scene files' poses match to micrometres);
b. (a) with each object's start pose jittered by ``JITTER_M`` along a random direction and
   ``JITTER_RAD`` about a random axis (the chaos of the pushes themselves);
c. the generator's world started from the scene files' true poses at rest;
d. (c) with friction ``PhysicsConfig().friction`` for every object (the generator draws one
   per object);
e. (d) with masses from ``PhysicsConfig().density_kg_m3`` times the mesh volume (the generator
   uses catalogue masses);
f. (e) with each object's convex hull as its mesh (and mass from the hull's volume);
g. the inference world as it is: ``ipr_shapes.physics.build_world`` with the true shapes' hulls at the
   true frame-0 poses on the support perception found, default ``PhysicsConfig``
   (``benchmarks.dev_push_replay.replay_errors``);
h. (g) with a stiff, position-controlled pusher (``ipr_shapes.physics.STIFF_PUSHER``: contact
   time constant 4 ms at a 2 ms push step, where (g) has MuJoCo's soft default at the default step), the
   generator's pusher contact: whether the pusher's model matters in the inference world.

The generator's world is rebuilt by replaying the accepted attempt's draws up to the settled
pile (the same order as ``ipr_shapes.synth.generate._attempt``), and the rebuilt pile is checked
against the scene's frame-0 ground truth: a generator change that breaks the replay fails
loudly instead of measuring a different world. Benchmark code may read the ground truth;
inference never does.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from benchmarks.common import markdown_table

#: A pair counts as moved when its true motion exceeds this (m).
MOVED_M = 0.005
#: Rung (b): start-pose jitter, translation (m) and rotation (rad).
JITTER_M = 1e-4
JITTER_RAD = 1e-3
#: Scenes of the ycb-dynamic suite the page's ladder replays (its first ones; None: all, about
#: 15 s per scene on 2 shared cores).
LADDER_SCENES: int | None = None
#: A rebuilt pile farther than this (m, any object's origin) from frame 0's truth is refused
#: (the files and their world frame agree with the generator to a few micrometres).
REBUILD_TOLERANCE_M = 1e-4

#: Rung key -> its line in the table.
RUNGS = {
    "a": "generator's world, its own saved state",
    "b": "(a), start poses jittered 0.1 mm / 1 mrad",
    "c": "generator's world, true poses",
    "d": "(c) + friction 1.0 for all",
    "e": "(d) + masses from a uniform density",
    "f": "(e) + convex hulls",
    "g": "the inference world as it is (`ipr_shapes.physics`)",
    "h": "(g) + a stiff pusher at a 2 ms push step",
}


def motion_error(
    points: np.ndarray, simulated: np.ndarray, true: np.ndarray
) -> tuple[float, float]:
    """(error, true motion) in metres: the mean distance between the points (K, 3, world frame
    at frame 0) moved by the simulated and by the true rigid motion (4, 4 each, world frame,
    since frame 0), and the points' mean true motion."""

    def moved(transform: np.ndarray) -> np.ndarray:
        return points @ transform[:3, :3].T + transform[:3, 3]

    error = np.linalg.norm(moved(simulated) - moved(true), axis=1).mean()
    motion = np.linalg.norm(moved(true) - points, axis=1).mean()
    return float(error), float(motion)


# --------------------------------------------------------------------------------------------
# The generator's world


@dataclasses.dataclass(frozen=True)
class GeneratorScene:
    """A dynamic scene with the generator's settled pile rebuilt (frame 0).

    ``world`` holds the saved state; ``state`` its integration state; ``truth[frame]`` (n, 4,
    4) the true world-from-model poses per frame in ``world.objects`` order; ``hulls[i]`` (K,
    3) object i's hull vertices (model frame, m); ``pushes`` the recorded pushes."""

    world: object
    state: np.ndarray
    truth: dict[int, np.ndarray]
    hulls: list[np.ndarray]
    pushes: tuple


def _synth_config(values: dict):
    from ipr_shapes.synth import SynthConfig

    names = {f.name for f in dataclasses.fields(SynthConfig)}
    return SynthConfig(
        **{k: tuple(v) if isinstance(v, list) else v for k, v in values.items() if k in names}
    )


def rebuild_generator_scene(path: Path) -> GeneratorScene:
    """The generator's world of scene ``path`` at frame 0 (``synth.json``'s seed, attempt and
    configuration, the YCB models of ``ipr_shapes.data.ycb_models_dir``). Raises ValueError when the
    scene was not written by ``ipr-shapes synth`` as a dynamic scene or the rebuilt pile differs from
    the scene's frame-0 ground truth."""
    from ipr_shapes.scene import load_ground_truth, load_scene
    from ipr_shapes.synth import object_pool
    from ipr_shapes.synth.piles import PileWorld, Rejected, sample_layout

    info_path = path / "synth.json"
    if not info_path.is_file():
        raise ValueError(
            f"{path}: no synth.json; the ladder replays scenes from `ipr-shapes synth`"
        )
    info = json.loads(info_path.read_text(encoding="utf-8"))
    if info.get("kind") != "dynamic":
        raise ValueError(f"{info_path}: kind {info.get('kind')!r}, the ladder needs pushes")
    config = dataclasses.replace(
        _synth_config(info["config"]), object_source=info.get("object_source", "auto")
    )
    pool, _ = object_pool(None, config)
    arrangement = info["arrangement"]
    attempt = int(info["attempts"]) - 1
    # The draws of ipr_shapes.synth.generate._attempt, in its order, up to the settled pile.
    rng = np.random.default_rng(np.random.SeedSequence(int(info["seed"]), spawn_key=(attempt,)))
    if arrangement != "table":
        pool = [item for item in pool if item.extents.max() <= config.boxed_max_extent_m] or pool
    count = min(int(rng.integers(config.min_objects, config.max_objects + 1)), len(pool))
    objects = [pool[i] for i in rng.choice(len(pool), count, replace=False)]
    layout = sample_layout(arrangement, objects, rng, config)
    frictions = rng.uniform(*config.friction, count)
    light_azimuth, light_elevation = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(50, 80))
    light_dir = -np.array(
        [
            np.cos(light_elevation) * np.cos(light_azimuth),
            np.cos(light_elevation) * np.sin(light_azimuth),
            np.sin(light_elevation),
        ]
    )
    world = PileWorld(layout, objects, frictions, config, light_dir)
    try:
        world.drop_all(rng)
    except Rejected as error:
        raise ValueError(
            f"{path}: the rebuilt pile is not the scene's (the generator rejects it: {error}); "
            "the generator changed since the scene was written (regenerate the scenes)"
        ) from error

    scene = load_scene(path)
    world_from_camera = {f.index: f.world_from_camera for f in scene.frames}
    truth: dict[int, np.ndarray] = {}
    for frame, entries in load_ground_truth(path).items():
        if [e.obj_id for e in entries] != [item.obj_id for item in objects]:
            raise ValueError(f"{path}: the rebuilt pile has other objects than scene_gt.json")
        truth[frame] = np.stack([world_from_camera[frame] @ e.camera_from_model for e in entries])
    offset = np.abs(world.poses()[:, :3, 3] - truth[0][:, :3, 3]).max()
    if offset > REBUILD_TOLERANCE_M:
        raise ValueError(
            f"{path}: the rebuilt pile is {offset * 1e3:.3f} mm from frame 0's ground truth; "
            "the generator changed since the scene was written (regenerate the scenes)"
        )
    hulls = [item.hull_vertices for item in objects]
    return GeneratorScene(world, world.save(), truth, hulls, tuple(scene.pushes))


def _set_poses(world, poses: np.ndarray) -> None:
    """Place the generator world's objects at ``poses`` (n, 4, 4), at rest."""
    import mujoco
    from scipy.spatial.transform import Rotation

    for index, pose in enumerate(poses):
        adr, vel = world.qpos_adr[index], world.qvel_adr[index]
        world.data.qpos[adr : adr + 3] = pose[:3, 3]
        x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
        world.data.qpos[adr + 3 : adr + 7] = [w, x, y, z]
        world.data.qvel[vel : vel + 6] = 0.0
    mujoco.mj_forward(world.model, world.data)


def jittered(poses: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``poses`` (n, 4, 4) each moved by ``JITTER_M`` along a random direction and turned by
    ``JITTER_RAD`` about a random axis through its origin."""
    from scipy.spatial.transform import Rotation

    result = poses.copy()
    for pose in result:
        direction = rng.normal(size=3)
        axis = rng.normal(size=3)
        pose[:3, 3] += JITTER_M * direction / np.linalg.norm(direction)
        turn = Rotation.from_rotvec(JITTER_RAD * axis / np.linalg.norm(axis)).as_matrix()
        pose[:3, :3] = turn @ pose[:3, :3]
    return result


def _replay_generator(world, scene: GeneratorScene) -> list[tuple[float, float]]:
    """Replay the pushes in a generator world placed at its start; (error, motion) pairs. An
    object that falls off the table is measured where it fell."""
    from ipr_shapes.synth.piles import Rejected

    start = world.poses()
    rows = []
    for frame in sorted(scene.truth)[1:]:
        for push in scene.pushes:
            if push.after_frame == frame:
                with contextlib.suppress(Rejected):
                    world.run_push(push.start_m, push.direction, push.distance_m, push.speed_m_s)
        now = world.poses()
        for k, hull in enumerate(scene.hulls):
            first = scene.truth[0][k]
            points = hull @ first[:3, :3].T + first[:3, 3]  # world frame at frame 0
            true = scene.truth[frame][k] @ np.linalg.inv(first)
            simulated = now[k] @ np.linalg.inv(start[k])
            rows.append(motion_error(points, simulated, true))
    return rows


def _variant_world(scene: GeneratorScene, *, friction=None, density=None, hulls=False):
    """A generator world like ``scene.world`` with every object's friction, masses from a
    density (kg/m^3) times the (hull) volume, and/or convex hulls as meshes."""
    import trimesh

    from ipr_shapes.synth.piles import PileWorld

    base = scene.world
    objects = []
    for item in base.objects:
        if hulls:
            hull = trimesh.Trimesh(item.vertices, item.faces).convex_hull
            item = dataclasses.replace(
                item,
                vertices=np.asarray(hull.vertices, dtype=np.float64),
                faces=np.asarray(hull.faces, dtype=np.int32),
                colors=np.full((len(hull.vertices), 3), 200, dtype=np.uint8),
                volume_m3=float(hull.volume),
            )
        if density is not None:
            item = dataclasses.replace(item, mass_kg=float(density * item.volume_m3))
        objects.append(item)
    frictions = base.frictions if friction is None else np.full(len(objects), friction)
    world = PileWorld(base.layout, objects, frictions, base.config, base.light_dir)
    world.model.body_gravcomp[world.body_ids] = 0.0  # a new world's objects float, parked
    world.dropped[:] = True
    return world


def generator_rungs(scene: GeneratorScene, seed: int = 0) -> dict[str, list[tuple[float, float]]]:
    """Rungs (a)-(f) of one scene: rung key -> (error, true motion) per (object, later frame)."""
    from ipr_shapes.physics import PhysicsConfig

    physics = PhysicsConfig()
    world = scene.world
    rows: dict[str, list[tuple[float, float]]] = {}
    world.restore(scene.state)
    rows["a"] = _replay_generator(world, scene)
    world.restore(scene.state)
    _set_poses(world, jittered(world.poses(), np.random.default_rng(seed)))
    rows["b"] = _replay_generator(world, scene)
    world.restore(scene.state)
    _set_poses(world, scene.truth[0])
    rows["c"] = _replay_generator(world, scene)
    variants = {
        "d": {"friction": physics.friction},
        "e": {"friction": physics.friction, "density": physics.density_kg_m3},
        "f": {"friction": physics.friction, "density": physics.density_kg_m3, "hulls": True},
    }
    for key, settings in variants.items():
        variant = _variant_world(scene, **settings)
        _set_poses(variant, scene.truth[0])
        rows[key] = _replay_generator(variant, scene)
    return rows


def inference_rung(path: Path, stiff_pusher: bool = False) -> list[tuple[float, float]]:
    """Rung (g): the inference world as it is (default ``PhysicsConfig``); (h) with
    ``stiff_pusher``."""
    from benchmarks.dev_push_replay import replay_errors
    from ipr_shapes.physics import STIFF_PUSHER, PhysicsConfig

    return replay_errors(path, PhysicsConfig(**(STIFF_PUSHER if stiff_pusher else {})))


def scene_ladder(path: Path) -> dict[str, list[tuple[float, float]]]:
    """Every rung of one scene: rung key -> (error, true motion) pairs (m)."""
    rows = generator_rungs(rebuild_generator_scene(Path(path)))
    rows["g"] = inference_rung(Path(path))
    rows["h"] = inference_rung(Path(path), stiff_pusher=True)
    return rows


# --------------------------------------------------------------------------------------------
# Statistics and the table


def rung_figures(pairs: Sequence[tuple[float, float]]) -> dict:
    """Over the pairs that truly moved more than ``MOVED_M``: {"moved" (count), "motion" (median
    true motion), "median", "q25", "q75" (simulated-vs-true error)}, in mm (nan when none);
    "still" the median error of the pairs that did not move."""
    array = np.asarray(pairs, dtype=np.float64).reshape(-1, 2) * 1e3
    errors, motions = array[:, 0], array[:, 1]
    moved = motions > MOVED_M * 1e3

    def stat(values: np.ndarray, q: float) -> float:
        return float(np.percentile(values, q)) if values.size else float("nan")

    return {
        "moved": int(moved.sum()),
        "motion": stat(motions[moved], 50),
        "median": stat(errors[moved], 50),
        "q25": stat(errors[moved], 25),
        "q75": stat(errors[moved], 75),
        "still": stat(errors[~moved], 50),
    }


def ladder_table(rows: dict[str, list[tuple[float, float]]]) -> str:
    """The markdown table of pooled rows (rung key -> pairs)."""

    def mm(value: float) -> str:
        return f"{value:.1f}" if np.isfinite(value) else "-"

    table = []
    for key, label in RUNGS.items():
        figures = rung_figures(rows.get(key, []))
        table.append(
            [
                f"({key}) {label}",
                figures["moved"],
                mm(figures["median"]),
                f"{mm(figures['q25'])}-{mm(figures['q75'])}" if figures["moved"] else "-",
                mm(figures["still"]),
            ]
        )
    return markdown_table(
        ["world", "moved pairs", "error median mm", "quartiles mm", "still objects mm"], table
    )


def ladder(
    scenes: Sequence[Path], progress: Callable[[str], None] | None = None
) -> tuple[dict[str, list[tuple[float, float]]], list[str]]:
    """Pooled pairs over ``scenes`` per rung and the failures ("scene: reason")."""
    pooled: dict[str, list[tuple[float, float]]] = {key: [] for key in RUNGS}
    failures = []
    for number, path in enumerate(scenes, 1):
        started = time.perf_counter()
        try:
            rows = scene_ladder(Path(path))
        except Exception as error:  # noqa: BLE001 - a failing scene is listed, not a crash
            failures.append(f"{Path(path).name}: {type(error).__name__}: {error}")
            rows = {}
        for key, pairs in rows.items():
            pooled[key] += pairs
        if progress:
            progress(
                f"bench: replay {number}/{len(scenes)} {Path(path).name} "
                f"{time.perf_counter() - started:.1f} s"
                + (f" FAILED {failures[-1]}" if not rows else "")
            )
    return pooled, failures


def section(scenes: Sequence[Path], suite: str = "ycb-dynamic") -> str:
    """The page's markdown for the ladder over ``scenes``."""
    started = time.perf_counter()
    pooled, failures = ladder(scenes, progress=lambda line: print(line, flush=True))
    motion = rung_figures(pooled["a"])["motion"]
    lines = [
        "## Replaying the pushes: how far the simulator is from the data",
        "",
        f"The recorded pushes of {len(scenes)} {suite} scenes replayed in worlds "
        "that go step by step from the generator's own simulation (`ipr_shapes.synth`) to the world "
        "inference builds (`ipr_shapes.physics`), with the true shapes (`benchmarks.replay`). After "
        "each push, every object's simulated motion since frame 0 is compared with its true "
        "motion: the mean distance between its true convex hull's vertices moved by each. "
        f"Figures over the (object, frame) pairs that truly moved more than {MOVED_M * 1e3:g} "
        f"mm (median true motion {motion:.1f} mm); `still objects`: the median error of the "
        "pairs that did not move. Rungs (c)-(f) start from the scene files' true poses at "
        "rest; (g) and (h) from them on the support perception found, settled first. Errors far above "
        "zero in (b) mean the pushes are chaotic: a likelihood must expect that much noise.",
        "",
        ladder_table(pooled),
        "",
        "Failed: " + ("; ".join(f"`{f}`" for f in failures) or "none") + ".",
        "",
        f"_Replay benchmark time: {time.perf_counter() - started:.0f} s._",
        "",
    ]
    return "\n".join(lines)


def run(suites: dict[str, list[Path]]) -> str:
    """The ``replay`` section of docs/BENCHMARKS.md: the ladder on the first
    ``LADDER_SCENES`` ycb-dynamic scenes (all: None)."""
    return section(list(suites.get("ycb-dynamic", []))[:LADDER_SCENES])


def main(argv: list[str] | None = None) -> int:
    """Print the ladder table for a few scenes; the page is not touched."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", type=Path, action="append", help="scene folder (repeatable)")
    parser.add_argument("--limit", type=int, help="the ycb-dynamic suite's first N scenes")
    args = parser.parse_args(argv)
    if args.limit is not None and args.limit < 1:
        parser.error("--limit must be at least 1")
    if args.scene:
        scenes = list(args.scene)
        for scene in scenes:
            if not (scene / "synth.json").is_file():
                parser.error(f"{scene}: not a scene written by `ipr-shapes synth` (no synth.json)")
    else:
        from ipr_shapes.suites import suite_scenes

        scenes = suite_scenes("ycb-dynamic")[: args.limit]
    print(section(scenes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
