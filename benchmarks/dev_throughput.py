"""Sampling throughput of IPR inference: joint samples per CPU-second against MuJoCo's own
stepping rate (docs/experiments/2026-11-26-sampling-throughput.md).

Usage::

    python -m benchmarks.dev_throughput SCENE [SCENE ...] [--samples 20] [--workers 1]
        [--config FILE]

Per scene: perception, fusion and hypotheses as ``ipr-shapes infer`` runs them (default configuration
or ``--config``'s TOML, ``ipr+action+uniform``), then ``--samples`` tree samples with their likelihoods in one run of
``ipr_shapes.inference.run_samples``. Reported: CPU seconds of the sampling (``time.process_time``:
the machine is shared, so wall time says little), the CPU seconds inside ``mujoco.mj_step``
and the steps taken (MuJoCo's raw stepping rate is steps / stepping CPU; if sampling did
nothing but step, it would reach steps per sample / that rate), world compilations, stability
tests, candidates screened, candidates' test results reused in another context and distinct
joint models. One JSON line per scene on stdout.

To compare code versions, run it under each (``PYTHONPATH=<their src>``): the script only uses
``Sampler`` attributes both have, and reads ``screened`` and ``reused`` when present.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def measure(path: Path, samples: int, workers: int, config=None) -> dict:
    """One scene's sampling throughput (module doc) under ``config`` (a ``Config``; None: the
    default)."""
    import mujoco
    import numpy as np

    import ipr_shapes.inference.pool as pool
    import ipr_shapes.inference.sampler as sampler_module
    import ipr_shapes.physics as physics
    from ipr_shapes.collision_checker import uniform_posteriors
    from ipr_shapes.config import Config
    from ipr_shapes.hypotheses import prepare_hypotheses
    from ipr_shapes.inference import build_problem
    from ipr_shapes.likelihood import observed_frames
    from ipr_shapes.methods import METHODS
    from ipr_shapes.pipeline import fuse, perceive
    from ipr_shapes.scene import load_scene

    scene = load_scene(path)
    config = config or Config()
    method = METHODS["ipr+action+uniform"]
    perception = perceive(scene, config)
    fused = fuse(scene, perception, method, config)
    prepared = prepare_hypotheses(
        fused.objects, perception.free_space[0], perception.planes[0], config.hypotheses,
        config.constraints, np.random.default_rng(0), None, fused.object_spaces, None,
    )  # fmt: skip
    uniform = uniform_posteriors(prepared, config.collision_checker, np.random.default_rng(0))
    observed = observed_frames(
        scene.frames, perception.labels, config.inference.likelihood.decimation
    )
    problem, _ = build_problem(
        prepared, uniform, perception.planes[0], observed, variant=method,
        pusher=scene.pusher, pushes=scene.pushes, config=config.inference, seed=0,
    )  # fmt: skip

    stats = {"step_cpu_s": 0.0, "steps": 0, "build_cpu_s": 0.0, "builds": 0}
    step, build = mujoco.mj_step, physics.build_world

    def timed_step(model, data, nstep=1):
        started = time.thread_time()
        step(model, data, nstep=nstep)
        stats["step_cpu_s"] += time.thread_time() - started
        stats["steps"] += nstep

    def timed_build(*args, **kwargs):
        started = time.thread_time()
        world = build(*args, **kwargs)
        stats["build_cpu_s"] += time.thread_time() - started
        stats["builds"] += 1
        return world

    samplers = []
    original_sampler = pool.Sampler

    def keep(problem):
        samplers.append(original_sampler(problem))
        return samplers[-1]

    mujoco.mj_step, physics.build_world, sampler_module.build_world = (
        timed_step, timed_build, timed_build,
    )  # fmt: skip
    pool.Sampler = keep
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        results = pool.run_samples(
            problem, ((index, None) for index in range(samples)),
            workers=workers, deadline=float("inf"),
        )  # fmt: skip
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        mujoco.mj_step, physics.build_world, sampler_module.build_world = step, build, build
        pool.Sampler = original_sampler
    sampler = samplers[-1] if samplers else None
    steps_per_sample = stats["steps"] / max(len(results), 1)
    raw_rate = stats["steps"] / stats["step_cpu_s"] if stats["step_cpu_s"] else float("nan")
    return {
        "scene": path.name,
        "objects": problem.count,
        "candidates": [len(c) for c in problem.candidates],
        "samples": len(results),
        "workers": workers,
        "wall_s": wall,
        "cpu_s": cpu,
        "samples_per_cpu_s": len(results) / cpu,
        **stats,
        "raw_steps_per_cpu_s": raw_rate,
        "stepping_bound_samples_per_cpu_s": raw_rate / steps_per_sample,
        "stability_tests": getattr(sampler, "stability_tests", None),
        "screened": getattr(sampler, "screened", None),
        "reused": getattr(sampler, "reused", None),
        "distinct_models": len(sampler.evaluated) if sampler else None,
        "choices": [list(r.choice) for r in results],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", type=Path, nargs="+", help="scene folders")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--config", type=Path, help="a TOML configuration (ipr-shapes config show)")
    args = parser.parse_args(argv)
    config = None
    if args.config is not None:
        from ipr_shapes.config import read_config
        from ipr_shapes.errors import IprError

        try:
            config = read_config(args.config)
        except IprError as error:
            parser.exit(2, f"error: {error}\n")
    for path in args.scenes:
        print(json.dumps(measure(path, args.samples, args.workers, config)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
